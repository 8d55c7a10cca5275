//! `foisctl keygen`, `sign` and `image-info` as a user runs them: a key
//! pair, a signed image that verifies with its public key and not with
//! another, a one-bit-changed image refused, and the exit codes of the
//! refusals (a key never overwritten, a body too large, a file that is not
//! an image).
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::foisctl;

#[test]
fn keygen_sign_and_image_info_work_together_and_refuse_by_exit_code() {
    let dir = tempfile::tempdir().unwrap();
    let keys = dir.path().join("keys");
    let other = dir.path().join("other");
    let k = keys.to_str().unwrap();
    let (code, out, err) = foisctl(&["keygen", "--out", k]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("fois-update.pub"), "{out}");
    let (code, _, err) = foisctl(&["keygen", "--out", k]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("never overwrites"), "{err}");
    assert_eq!(foisctl(&["keygen", "--out", other.to_str().unwrap()]).0, 0);

    let bin = dir.path().join("app.bin");
    std::fs::write(
        &bin,
        (0..20_000u32).map(|i| (i % 251) as u8).collect::<Vec<_>>(),
    )
    .unwrap();
    let img = dir.path().join("app.fois");
    let key = keys.join("fois-update.key");
    let sign = |version: &str, bin: &std::path::Path, extra: &[&str]| {
        let mut a = vec![
            "sign",
            "--key",
            key.to_str().unwrap(),
            "--bin",
            bin.to_str().unwrap(),
            "--version",
            version,
            "--out",
            img.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        foisctl(&a)
    };
    let (code, out, err) = sign("0.7.0", &bin, &[]);
    assert_eq!(code, 0, "{out}{err}");
    assert_eq!(std::fs::metadata(&img).unwrap().len(), 20_000 + 128);

    let public = keys.join("fois-update.pub");
    let (code, out, err) = foisctl(&[
        "image-info",
        img.to_str().unwrap(),
        "--key",
        public.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    for want in [
        "version    0.7.0",
        "board      NUCLEO-F446RE",
        "flags      none",
        "body       20000 bytes",
        "image_len  20064 bytes",
        "signature  verifies",
    ] {
        assert!(out.contains(want), "{want}: {out}");
    }
    let wrong = other.join("fois-update.pub");
    let (code, _, err) = foisctl(&[
        "image-info",
        img.to_str().unwrap(),
        "--key",
        wrong.to_str().unwrap(),
    ]);
    assert_eq!(code, 14, "{err}");

    // One bit of the body changed: the signature no longer verifies.
    let mut bytes = std::fs::read(&img).unwrap();
    bytes[1234] ^= 0x04;
    let bad = dir.path().join("bad.fois");
    std::fs::write(&bad, &bytes).unwrap();
    let (code, _, err) = foisctl(&[
        "image-info",
        bad.to_str().unwrap(),
        "--key",
        public.to_str().unwrap(),
    ]);
    assert_eq!(code, 14, "{err}");

    // Not an image; a downgrade flag; a bad version; a body too large.
    assert_eq!(foisctl(&["image-info", bin.to_str().unwrap()]).0, 11);
    let (code, out, _) = sign("0.6.0", &bin, &["--downgrade"]);
    assert_eq!(code, 0);
    assert!(out.contains("signed downgrade"), "{out}");
    assert!(
        foisctl(&["image-info", img.to_str().unwrap()])
            .1
            .contains("flags      downgrade")
    );
    assert_eq!(sign("0.7", &bin, &[]).0, 2);
    let big = dir.path().join("big.bin");
    std::fs::write(&big, vec![0u8; 128 * 1024 - 64 + 1]).unwrap();
    let (code, _, err) = sign("0.7.0", &big, &[]);
    assert_eq!(code, 7, "{err}");
    assert!(err.contains("131009 bytes of body"), "{err}");
}
