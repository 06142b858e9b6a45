"""`python -m mitsuba_ref REQUEST.json`: run a request against a `voltab export mitsuba` folder."""
import json
import sys

from . import harness


def main(argv):
    if len(argv) != 2:
        print("usage: python -m mitsuba_ref REQUEST.json", file=sys.stderr)
        return 2
    try:
        with open(argv[1], encoding="utf-8") as f:
            request = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        print(f"{argv[1]}: cannot read the request: {e}", file=sys.stderr)
        return 2
    try:
        result = harness.run_request(request, base=argv[1])
    except harness.RequestError as e:
        print(f"{argv[1]}: {e}", file=sys.stderr)
        return 2
    print(f"wrote {result['out']}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
