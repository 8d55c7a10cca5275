//! The public key images are checked against (ed25519, 32 bytes).
//!
//! The board takes it from a file at build time (`firmware/README.md`,
//! "Updating over the link"); a build without one holds [`UpdateKey::NONE`],
//! which verifies no signature: such a node refuses every image
//! (`BadSignature`), it never accepts one. Tests use a test key pair kept
//! under `firmware/tests/`.

use fois_protocol::ImageSignature;
use fois_protocol::update::SIGNATURE_LEN;

/// Bytes of an ed25519 public key.
pub const PUBLIC_KEY_LEN: usize = 32;

/// The key the node verifies images with, or none.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UpdateKey(Option<[u8; PUBLIC_KEY_LEN]>);

impl UpdateKey {
    /// No key: every image is refused.
    pub const NONE: UpdateKey = UpdateKey(None);

    /// The key's 32 bytes (the compressed point `foisctl keygen` writes).
    pub const fn from_bytes(bytes: [u8; PUBLIC_KEY_LEN]) -> Self {
        UpdateKey(Some(bytes))
    }

    /// The key's bytes, if there is one.
    pub const fn bytes(&self) -> Option<&[u8; PUBLIC_KEY_LEN]> {
        self.0.as_ref()
    }

    /// True when `signature` signs `message` (the 64-byte SHA-512 of the
    /// image, as embassy-boot's `verify_and_mark_updated` checks it) with
    /// this key. Without a key, or with a key that is not a curve point,
    /// false.
    pub fn verifies(&self, message: &[u8; 64], signature: &ImageSignature) -> bool {
        let Some(key) = self.0.as_ref() else {
            return false;
        };
        let Ok(public) = salty::PublicKey::try_from(key) else {
            return false;
        };
        let bytes: [u8; SIGNATURE_LEN] = signature.to_bytes();
        let sig = salty::Signature::from(&bytes);
        public.verify(message, &sig).is_ok()
    }
}
