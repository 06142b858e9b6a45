use super::*;

#[test]
fn base64_round_trips_rfc4648_vectors() {
    for (plain, coded) in
        [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("foobar", "Zm9vYmFy")]
    {
        assert_eq!(decode_base64(coded).unwrap(), plain.as_bytes());
    }
    assert!(decode_base64("Zm9v*").unwrap_err().contains("invalid base64"));
}

#[test]
fn percent_decoding_rejects_broken_escapes_instead_of_panicking() {
    // Regression: the gltf crate's URI decoder unwraps here.
    assert_eq!(percent_decode("a%20b.bin").unwrap(), b"a b.bin");
    assert!(percent_decode("a%2").is_err());
    assert_eq!(percent_decode("%FF").unwrap(), [0xFF]);
}
