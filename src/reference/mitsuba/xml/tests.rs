use super::Element;

#[test]
fn nested_escaped_elements() {
    let doc = Element::new("scene")
        .attr("version", "3.0.0")
        .child(Element::rgb("radiance", [1.0, 0.5, 0.0]).comment("a -- b"))
        .child(Element::string("filename", "a&b\".ply"))
        .document();
    assert_eq!(
        doc,
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<scene version=\"3.0.0\">\n    <!-- a - - b -->\n    \
         <rgb name=\"radiance\" value=\"1.0, 0.5, 0\"/>\n    <string name=\"filename\" value=\"a&amp;b&quot;.ply\"/>\n</scene>\n"
    );
}
