"""Seeds for the glTF fuzz target: every bundled .gltf as-is and as a self-contained .glb (its .bin
as the BIN chunk), since the target reads documents from memory and refuses external files."""
import json, os, struct, sys

src, out = sys.argv[1], sys.argv[2]
for name in sorted(os.listdir(src)):
    if not name.endswith(".gltf"):
        continue
    with open(os.path.join(src, name), "rb") as f:
        raw = f.read()
    with open(os.path.join(out, name), "wb") as f:
        f.write(raw)
    doc = json.loads(raw)
    buffers = doc.get("buffers", [])
    if len(buffers) != 1 or "uri" not in buffers[0]:
        continue
    with open(os.path.join(src, buffers[0]["uri"]), "rb") as f:
        bin_ = f.read()
    del buffers[0]["uri"]
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    bin_ += b"\0" * (-len(bin_) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(bin_), b"BIN\0") + bin_
    with open(os.path.join(out, name[:-5] + ".glb"), "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
