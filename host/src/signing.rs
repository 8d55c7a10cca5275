//! Signed firmware images, host side: the ed25519 key pair's files
//! (`foisctl keygen`), signing an application binary into a signed image
//! (`foisctl sign`) and checking one (`foisctl image-info --key`).
//!
//! The signed message is the SHA-512 digest of `body | trailer` (64 bytes):
//! what embassy-boot's `verify_and_mark_updated` hashes from the update
//! slot and checks against the public key built into the firmware.
//! ed25519-dalek signs it (deterministic: the same key and bytes give the
//! same signature); the key's seed comes from the operating system's
//! random source (`getrandom`).
//!
//! Files: the secret key `fois-update.key` holds the 32-byte seed as 64 hex
//! digits (mode 0600, never overwritten); the public key `fois-update.pub`
//! 64 hex digits (what the firmware build reads).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use ed25519_dalek::{Signature, Signer, SigningKey, Verifier, VerifyingKey};
use fois_link::signed_image::{MAX_BODY_BYTES, SignedImage, hex};
use fois_protocol::update::image_flags;
use fois_protocol::{FirmwareVersion, Hello, ImageTrailer};

/// The secret key's file name in `keygen --out DIR`.
pub const SECRET_KEY_FILE: &str = "fois-update.key";
/// The public key's file name in `keygen --out DIR`.
pub const PUBLIC_KEY_FILE: &str = "fois-update.pub";
/// The board an image is for unless `--board` says otherwise.
pub const DEFAULT_BOARD: &str = "NUCLEO-F446RE";

/// What went wrong with keys or images.
#[derive(Debug, thiserror::Error)]
pub enum SigningError {
    /// A key file exists already.
    #[error(
        "{0} exists: keygen never overwrites a key (move it away first, or choose another --out)"
    )]
    Exists(PathBuf),
    /// A key file's content is not 64 hex digits.
    #[error("{path}: not a key file (64 hex digits expected): {why}")]
    BadKeyFile {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// The body is larger than an image may be.
    #[error(
        "{bytes} bytes of body: more than the {MAX_BODY_BYTES} an image may have (128 KiB less \
         the trailer)"
    )]
    BodyTooLarge {
        /// Bytes of the body.
        bytes: usize,
    },
    /// The board name does not fit the trailer.
    #[error("board name `{0}`: at most 16 ASCII characters")]
    BadBoard(String),
    /// The body is empty.
    #[error("the body is empty: nothing to sign")]
    EmptyBody,
    /// File I/O.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SigningError + '_ {
    move |source| SigningError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A new key pair from the operating system's random source.
pub fn generate() -> Result<SigningKey, SigningError> {
    let mut seed = [0u8; 32];
    getrandom::fill(&mut seed).map_err(|e| SigningError::Io {
        path: PathBuf::from("(random source)"),
        source: std::io::Error::other(e.to_string()),
    })?;
    Ok(SigningKey::from_bytes(&seed))
}

/// Write `key`'s files into `dir`: the secret (mode 0600) and the public
/// key; refuses when either exists. Returns their paths.
pub fn write_key_pair(dir: &Path, key: &SigningKey) -> Result<(PathBuf, PathBuf), SigningError> {
    let secret = dir.join(SECRET_KEY_FILE);
    let public = dir.join(PUBLIC_KEY_FILE);
    for p in [&secret, &public] {
        if p.exists() {
            return Err(SigningError::Exists(p.clone()));
        }
    }
    fs::create_dir_all(dir).map_err(io(dir))?;
    let mut opts = fs::OpenOptions::new();
    opts.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.mode(0o600);
    }
    let mut f = opts.open(&secret).map_err(io(&secret))?;
    writeln!(f, "{}", hex(key.as_bytes())).map_err(io(&secret))?;
    f.sync_all().map_err(io(&secret))?;
    fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&public)
        .and_then(|mut f| writeln!(f, "{}", hex(key.verifying_key().as_bytes())))
        .map_err(io(&public))?;
    Ok((secret, public))
}

/// 32 bytes from a file of 64 hex digits (blanks around them ignored).
fn read_hex32(path: &Path) -> Result<[u8; 32], SigningError> {
    let text = fs::read_to_string(path).map_err(io(path))?;
    parse_hex32(text.trim()).map_err(|why| SigningError::BadKeyFile {
        path: path.to_path_buf(),
        why,
    })
}

/// 32 bytes from 64 hex digits.
pub fn parse_hex32(text: &str) -> Result<[u8; 32], String> {
    if text.len() != 64 || !text.is_ascii() {
        return Err(format!("{} characters", text.chars().count()));
    }
    let mut out = [0u8; 32];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = u8::from_str_radix(&text[2 * i..2 * i + 2], 16)
            .map_err(|_| format!("`{}` is not hex", &text[2 * i..2 * i + 2]))?;
    }
    Ok(out)
}

/// The secret key of a `fois-update.key` file.
pub fn read_secret_key(path: &Path) -> Result<SigningKey, SigningError> {
    Ok(SigningKey::from_bytes(&read_hex32(path)?))
}

/// The public key of a `fois-update.pub` file.
pub fn read_public_key(path: &Path) -> Result<VerifyingKey, SigningError> {
    let bytes = read_hex32(path)?;
    VerifyingKey::from_bytes(&bytes).map_err(|e| SigningError::BadKeyFile {
        path: path.to_path_buf(),
        why: format!("not an ed25519 public key ({e})"),
    })
}

/// What to sign: the version, the board, a deliberate downgrade.
#[derive(Debug, Clone)]
pub struct SignRequest {
    /// The image's version.
    pub version: FirmwareVersion,
    /// The board it is for.
    pub board: String,
    /// It may replace a newer image.
    pub downgrade: bool,
}

/// Sign `body` into a signed image.
pub fn sign(key: &SigningKey, body: &[u8], req: &SignRequest) -> Result<SignedImage, SigningError> {
    if body.is_empty() {
        return Err(SigningError::EmptyBody);
    }
    if body.len() > MAX_BODY_BYTES {
        return Err(SigningError::BodyTooLarge { bytes: body.len() });
    }
    if req.board.is_empty() || req.board.len() > 16 || !req.board.is_ascii() {
        return Err(SigningError::BadBoard(req.board.clone()));
    }
    let trailer = ImageTrailer {
        body_len: body.len() as u32,
        version: req.version,
        flags: if req.downgrade {
            image_flags::DOWNGRADE
        } else {
            0
        },
        board: Hello::board_from_str(&req.board),
    };
    let mut signed = body.to_vec();
    signed.extend_from_slice(&trailer.to_bytes());
    let digest = fois_link::signed_image::sha512(&signed);
    let signature = key.sign(&digest).to_bytes();
    // Within MAX_BODY_BYTES and with a trailer just built: always reads back.
    SignedImage::assemble(body, &trailer, &signature).map_err(|e| SigningError::Io {
        path: PathBuf::from("(image)"),
        source: std::io::Error::other(e.to_string()),
    })
}

/// Whether `image`'s signature verifies with `key` (as the node checks it).
pub fn verifies(image: &SignedImage, key: &VerifyingKey) -> bool {
    let signature = Signature::from_bytes(&image.signature_bytes());
    key.verify(&image.digest(), &signature).is_ok()
}

/// `X.Y.Z`, each 0–255.
pub fn parse_version(s: &str) -> Result<FirmwareVersion, String> {
    let parts: Vec<&str> = s.trim().split('.').collect();
    let [a, b, c] = parts[..] else {
        return Err(format!("`{s}` is not a version MAJOR.MINOR.PATCH"));
    };
    let n = |p: &str| {
        p.parse::<u8>()
            .map_err(|_| format!("`{p}` in `{s}` is not a number 0–255"))
    };
    Ok([n(a)?, n(b)?, n(c)?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::update::TRAILER_LEN;

    /// RFC 8032 §7.1, TEST 1: the seed, its public key, the signature of
    /// the empty message.
    const RFC_SEED: &str = "9d61b19deffd5a60ba844af492ec2cc44449c5697b326919703bac031cae7f60";
    const RFC_PUBLIC: &str = "d75a980182b10ab7d54bfed3c964073a0ee172f3daa62325af021a68f707511a";
    const RFC_SIGNATURE: &str = "e5564300c360ac729086e2cc806e828a84877f1eb8e5d974d873e065224901555fb8821590a33bacc61e39701cf9b46bd25bf5f0595bbe24655141438e7a100b";

    fn rfc_key() -> SigningKey {
        SigningKey::from_bytes(&parse_hex32(RFC_SEED).unwrap())
    }

    #[test]
    fn the_key_and_signature_match_rfc_8032() {
        let key = rfc_key();
        assert_eq!(hex(key.verifying_key().as_bytes()), RFC_PUBLIC);
        assert_eq!(hex(&key.sign(b"").to_bytes()), RFC_SIGNATURE);
    }

    fn request() -> SignRequest {
        SignRequest {
            version: [1, 2, 3],
            board: DEFAULT_BOARD.into(),
            downgrade: false,
        }
    }

    #[test]
    fn a_signed_image_carries_its_trailer_and_verifies_and_one_bit_breaks_it() {
        let body: Vec<u8> = (0..5000u32).map(|i| (i * 31 + 7) as u8).collect();
        let key = rfc_key();
        let img = sign(&key, &body, &request()).unwrap();
        let bytes = img.as_bytes();
        assert_eq!(bytes.len(), 5000 + 64 + 64);
        // The trailer: magic, format 1, body length, version, flags, board.
        let t = &bytes[5000..5000 + TRAILER_LEN];
        assert_eq!(&t[..8], b"FOIS-IMG");
        assert_eq!(&t[8..10], &[1, 0]);
        assert_eq!(&t[10..14], &5000u32.to_le_bytes());
        assert_eq!(&t[14..18], &[1, 2, 3, 0]);
        assert_eq!(&t[18..31], b"NUCLEO-F446RE");
        assert!(t[31..].iter().all(|&b| b == 0));
        // The signature is ed25519 over SHA-512(body | trailer), checked
        // with the library directly.
        let digest = fois_link::signed_image::sha512(&bytes[..5064]);
        let sig = Signature::from_bytes(&bytes[5064..].try_into().unwrap());
        assert!(key.verifying_key().verify(&digest, &sig).is_ok());
        assert!(verifies(&img, &key.verifying_key()));
        // Deterministic: the same key and bytes, the same signature.
        assert_eq!(sign(&key, &body, &request()).unwrap(), img);
        // Any one bit changed, in the body, the trailer or the signature:
        // it no longer verifies (or no longer reads as an image).
        for pos in [0, 4999, 5000 + 14, 5000 + 17, 5064, bytes.len() - 1] {
            let mut bad = bytes.to_vec();
            bad[pos] ^= 0x01;
            match SignedImage::from_bytes(bad) {
                Ok(bad) => assert!(!verifies(&bad, &key.verifying_key()), "bit at {pos}"),
                Err(_) => assert!((5000..5064).contains(&pos)),
            }
        }
        // Another key does not verify it.
        let other = SigningKey::from_bytes(&[7; 32]);
        assert!(!verifies(&img, &other.verifying_key()));
        // The downgrade flag is signed.
        let down = sign(
            &key,
            &body,
            &SignRequest {
                downgrade: true,
                ..request()
            },
        )
        .unwrap();
        assert!(down.trailer().allows_downgrade());
        assert_ne!(down.signature_bytes(), img.signature_bytes());
    }

    #[test]
    fn too_large_or_empty_bodies_and_bad_boards_are_refused() {
        let key = rfc_key();
        assert!(sign(&key, &vec![0; MAX_BODY_BYTES], &request()).is_ok());
        assert!(matches!(
            sign(&key, &vec![0; MAX_BODY_BYTES + 1], &request()),
            Err(SigningError::BodyTooLarge { bytes }) if bytes == 128 * 1024 - 64 + 1
        ));
        assert!(matches!(
            sign(&key, &[], &request()),
            Err(SigningError::EmptyBody)
        ));
        let long = SignRequest {
            board: "A-BOARD-NAME-LONGER".into(),
            ..request()
        };
        assert!(matches!(
            sign(&key, &[1], &long),
            Err(SigningError::BadBoard(_))
        ));
    }

    #[test]
    fn key_files_are_private_never_overwritten_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let key = rfc_key();
        let (secret, public) = write_key_pair(dir.path(), &key).unwrap();
        assert_eq!(fs::read_to_string(&public).unwrap().trim(), RFC_PUBLIC);
        assert_eq!(fs::read_to_string(&secret).unwrap().trim(), RFC_SEED);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = fs::metadata(&secret).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o600);
        }
        assert_eq!(read_secret_key(&secret).unwrap().as_bytes(), key.as_bytes());
        assert_eq!(read_public_key(&public).unwrap(), key.verifying_key());
        let again = write_key_pair(dir.path(), &generate().unwrap());
        assert!(matches!(again, Err(SigningError::Exists(p)) if p == secret));
        assert_eq!(fs::read_to_string(&secret).unwrap().trim(), RFC_SEED);
        fs::write(&public, "abc\n").unwrap();
        assert!(matches!(
            read_public_key(&public),
            Err(SigningError::BadKeyFile { .. })
        ));
        // Two generated keys differ.
        assert_ne!(
            generate().unwrap().as_bytes(),
            generate().unwrap().as_bytes()
        );
    }

    #[test]
    fn versions_parse_as_three_bytes() {
        assert_eq!(parse_version("0.7.12"), Ok([0, 7, 12]));
        assert!(parse_version("1.2").is_err());
        assert!(parse_version("1.2.256").is_err());
        assert!(parse_version("1.x.3").is_err());
    }
}
