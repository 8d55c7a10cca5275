//! A signed firmware image file as `foisctl sign` writes it and the update
//! driver sends it: `body | trailer | signature`
//! (`fois_protocol::update`). Reading one checks its shape only (lengths,
//! trailer); the signature is the node's to check (and `foisctl
//! image-info --key`'s).

use fois_protocol::update::{SIGNATURE_LEN, TRAILER_LEN, TrailerError};
use fois_protocol::{FirmwareVersion, ImageSignature, ImageTrailer, UpdateBegin};
use sha2::{Digest, Sha512};

/// The most bytes of body and trailer a signed image holds: the
/// application image's budget (128 KiB), which the update slot takes.
pub const MAX_SIGNED_BYTES: usize = 128 * 1024;

/// The most bytes of a body (the application binary) that can be signed.
pub const MAX_BODY_BYTES: usize = MAX_SIGNED_BYTES - TRAILER_LEN;

/// Why bytes are not a signed image.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImageError {
    /// Shorter than a trailer and a signature.
    #[error(
        "{len} bytes: too short for a signed image (a body, a {TRAILER_LEN}-byte trailer and a \
         {SIGNATURE_LEN}-byte signature)"
    )]
    TooShort {
        /// Bytes read.
        len: usize,
    },
    /// More body and trailer than the update slot takes.
    #[error(
        "{signed_bytes} bytes of body and trailer: more than the {MAX_SIGNED_BYTES} an image \
         may have"
    )]
    TooLong {
        /// Body and trailer bytes.
        signed_bytes: usize,
    },
    /// The trailer cannot be read.
    #[error("no FOIS image trailer before the signature ({0:?}): not a file from `foisctl sign`")]
    Trailer(TrailerError),
    /// The trailer's body length is not the body's.
    #[error("the trailer says the body has {trailer} bytes, the file has {actual}")]
    BodyLength {
        /// What the trailer says.
        trailer: u32,
        /// What the file holds.
        actual: usize,
    },
}

/// A signed image, read and checked for shape.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SignedImage {
    bytes: Vec<u8>,
    trailer: ImageTrailer,
}

impl SignedImage {
    /// Read the bytes of a signed image file.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<SignedImage, ImageError> {
        let len = bytes.len();
        let signed_len = len
            .checked_sub(SIGNATURE_LEN)
            .filter(|&n| n > TRAILER_LEN)
            .ok_or(ImageError::TooShort { len })?;
        if signed_len > MAX_SIGNED_BYTES {
            return Err(ImageError::TooLong {
                signed_bytes: signed_len,
            });
        }
        let body_len = signed_len - TRAILER_LEN;
        let mut raw = [0u8; TRAILER_LEN];
        raw.copy_from_slice(&bytes[body_len..signed_len]);
        let trailer = ImageTrailer::parse(&raw).map_err(ImageError::Trailer)?;
        if trailer.body_len as usize != body_len {
            return Err(ImageError::BodyLength {
                trailer: trailer.body_len,
                actual: body_len,
            });
        }
        Ok(SignedImage { bytes, trailer })
    }

    /// Put a body, its trailer and the signature together (what `foisctl
    /// sign` writes).
    pub fn assemble(
        body: &[u8],
        trailer: &ImageTrailer,
        signature: &[u8; SIGNATURE_LEN],
    ) -> Result<SignedImage, ImageError> {
        let mut bytes = Vec::with_capacity(body.len() + TRAILER_LEN + SIGNATURE_LEN);
        bytes.extend_from_slice(body);
        bytes.extend_from_slice(&trailer.to_bytes());
        bytes.extend_from_slice(signature);
        SignedImage::from_bytes(bytes)
    }

    /// The whole file.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The bytes the node writes and the signature covers: body and trailer.
    pub fn signed_bytes(&self) -> &[u8] {
        &self.bytes[..self.bytes.len() - SIGNATURE_LEN]
    }

    /// The application binary.
    pub fn body(&self) -> &[u8] {
        &self.bytes[..self.trailer.body_len as usize]
    }

    /// The trailer.
    pub fn trailer(&self) -> &ImageTrailer {
        &self.trailer
    }

    /// The image's version.
    pub fn version(&self) -> FirmwareVersion {
        self.trailer.version
    }

    /// The board the image is for, without its zero padding.
    pub fn board_name(&self) -> String {
        board_text(&self.trailer.board)
    }

    /// The ed25519 signature's bytes.
    pub fn signature_bytes(&self) -> [u8; SIGNATURE_LEN] {
        let mut out = [0u8; SIGNATURE_LEN];
        out.copy_from_slice(&self.bytes[self.bytes.len() - SIGNATURE_LEN..]);
        out
    }

    /// The signature as the verify command carries it.
    pub fn signature(&self) -> ImageSignature {
        ImageSignature::from_bytes(&self.signature_bytes())
    }

    /// Bytes the node writes (body and trailer): the begin's `image_len`.
    pub fn image_len(&self) -> u32 {
        // At most MAX_SIGNED_BYTES (checked when read).
        self.signed_bytes().len() as u32
    }

    /// SHA-512 of body and trailer: the message the signature signs.
    pub fn digest(&self) -> [u8; 64] {
        sha512(self.signed_bytes())
    }

    /// The transfer's first command.
    pub fn begin(&self) -> UpdateBegin {
        let mut image_digest = [0u8; 32];
        image_digest.copy_from_slice(&self.digest()[..32]);
        UpdateBegin {
            image_len: self.image_len(),
            version: self.version(),
            image_digest,
        }
    }
}

/// SHA-512 of `bytes`.
pub fn sha512(bytes: &[u8]) -> [u8; 64] {
    let mut out = [0u8; 64];
    out.copy_from_slice(&Sha512::digest(bytes));
    out
}

/// A zero-padded board field as text (`?` for bytes that are not UTF-8).
pub fn board_text(board: &[u8; 16]) -> String {
    let end = board.iter().position(|&b| b == 0).unwrap_or(board.len());
    String::from_utf8(board[..end].to_vec()).unwrap_or_else(|_| "?".into())
}

/// Lower-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::Hello;

    fn trailer(body_len: u32) -> ImageTrailer {
        ImageTrailer {
            body_len,
            version: [0, 7, 0],
            flags: 0,
            board: Hello::board_from_str("NUCLEO-F446RE"),
        }
    }

    #[test]
    fn an_image_splits_into_body_trailer_and_signature() {
        let body: Vec<u8> = (0..1000u32).map(|i| (i * 7) as u8).collect();
        let img = SignedImage::assemble(&body, &trailer(1000), &[0xA5; 64]).unwrap();
        assert_eq!(img.as_bytes().len(), 1000 + 64 + 64);
        assert_eq!(img.body(), &body[..]);
        assert_eq!(img.image_len(), 1064);
        assert_eq!(&img.signed_bytes()[1000..1008], b"FOIS-IMG");
        assert_eq!(img.signature_bytes(), [0xA5; 64]);
        assert_eq!(img.board_name(), "NUCLEO-F446RE");
        let begin = img.begin();
        assert_eq!(begin.image_len, 1064);
        assert_eq!(begin.version, [0, 7, 0]);
        assert_eq!(begin.image_digest[..], img.digest()[..32]);
        // The SHA-512 of "abc" (FIPS 180-2's example) starts ddaf35a1.
        assert_eq!(&hex(&sha512(b"abc"))[..16], "ddaf35a193617aba");
    }

    #[test]
    fn foreign_or_damaged_files_are_refused_with_their_reason() {
        assert_eq!(
            SignedImage::from_bytes(vec![0; 128]),
            Err(ImageError::TooShort { len: 128 })
        );
        assert!(matches!(
            SignedImage::from_bytes(vec![0; 4096]),
            Err(ImageError::Trailer(TrailerError::NoMagic))
        ));
        let err = SignedImage::assemble(&[1; 10], &trailer(11), &[0; 64]).unwrap_err();
        assert_eq!(
            err,
            ImageError::BodyLength {
                trailer: 11,
                actual: 10
            }
        );
        let big = vec![0; MAX_BODY_BYTES + 1];
        let err = SignedImage::assemble(&big, &trailer(big.len() as u32), &[0; 64]).unwrap_err();
        assert_eq!(
            err,
            ImageError::TooLong {
                signed_bytes: MAX_SIGNED_BYTES + 1
            }
        );
        let max = vec![0; MAX_BODY_BYTES];
        assert!(SignedImage::assemble(&max, &trailer(max.len() as u32), &[0; 64]).is_ok());
    }
}
