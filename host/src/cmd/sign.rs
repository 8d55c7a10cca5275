//! `foisctl keygen`, `foisctl sign`, `foisctl image-info`: the update key
//! pair, a signed image from an application binary, and what a signed
//! image says (and whether a public key verifies it). The work is
//! [`crate::signing`]'s.

use std::path::PathBuf;

use clap::Args;
use fois_link::signed_image::{SignedImage, hex};
use fois_link::text::version_text;

use crate::exit::{self, Exit};
use crate::signing::{self, DEFAULT_BOARD, SignRequest, SigningError};

/// `foisctl keygen`.
#[derive(Debug, Args)]
pub struct KeygenArgs {
    /// Directory for `fois-update.key` (secret, mode 0600) and
    /// `fois-update.pub`; neither may exist. Keep the secret off the build
    /// machine's repository (README.md, "The update key").
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// `foisctl sign`.
#[derive(Debug, Args)]
pub struct SignArgs {
    /// The secret key file (`fois-update.key`).
    #[arg(long, value_name = "KEY")]
    pub key: PathBuf,
    /// The application binary, as linked for the active slot (`objcopy -O
    /// binary`).
    #[arg(long, value_name = "APP.bin")]
    pub bin: PathBuf,
    /// The image's version, MAJOR.MINOR.PATCH (the firmware's own).
    #[arg(long, value_name = "X.Y.Z", value_parser = signing::parse_version)]
    pub version: fois_protocol::FirmwareVersion,
    /// The board the image is for (as the node's Hello names it).
    #[arg(long, value_name = "NAME", default_value = DEFAULT_BOARD)]
    pub board: String,
    /// The image may replace a newer one: a deliberate, signed downgrade.
    #[arg(long)]
    pub downgrade: bool,
    /// The signed image to write.
    #[arg(long, value_name = "IMAGE.fois")]
    pub out: PathBuf,
}

/// `foisctl image-info`.
#[derive(Debug, Args)]
pub struct ImageInfoArgs {
    /// The signed image.
    #[arg(value_name = "IMAGE.fois")]
    pub image: PathBuf,
    /// A public key file (`fois-update.pub`): say whether the signature
    /// verifies with it (exit 14 when not).
    #[arg(long, value_name = "PUB")]
    pub key: Option<PathBuf>,
}

/// `foisctl keygen --out DIR`.
pub fn keygen(args: &KeygenArgs) -> anyhow::Result<()> {
    let key = signing::generate()?;
    let (secret, public) = signing::write_key_pair(&args.out, &key)?;
    println!("wrote {} (secret, mode 0600)", secret.display());
    println!(
        "wrote {} (public: {})",
        public.display(),
        hex(key.verifying_key().as_bytes())
    );
    println!(
        "build the firmware with it: copy the .pub to firmware/keys/fois-update.pub or set \
         FOIS_UPDATE_PUBLIC_KEY={}; move the .key to the signing machine or token \
         (README.md, \"The update key\")",
        public.display()
    );
    Ok(())
}

/// `foisctl sign ...`.
pub fn sign(args: &SignArgs) -> anyhow::Result<()> {
    let key = signing::read_secret_key(&args.key)?;
    let body =
        std::fs::read(&args.bin).map_err(|e| anyhow::anyhow!("{}: {e}", args.bin.display()))?;
    let req = SignRequest {
        version: args.version,
        board: args.board.clone(),
        downgrade: args.downgrade,
    };
    let image = signing::sign(&key, &body, &req).map_err(|e| match e {
        SigningError::BodyTooLarge { .. } | SigningError::BadBoard(_) | SigningError::EmptyBody => {
            anyhow::Error::from(Exit::new(exit::INVALID_VALUE, e.to_string()))
        }
        e => e.into(),
    })?;
    std::fs::write(&args.out, image.as_bytes())
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.out.display()))?;
    println!(
        "wrote {}: version {} for {}{}, {} bytes (body {} + trailer + signature)",
        args.out.display(),
        version_text(image.version()),
        image.board_name(),
        if args.downgrade {
            " (a signed downgrade)"
        } else {
            ""
        },
        image.as_bytes().len(),
        image.body().len()
    );
    Ok(())
}

/// Read a signed image file; not one: exit 11.
pub fn read_image(path: &std::path::Path) -> anyhow::Result<SignedImage> {
    let bytes = std::fs::read(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    SignedImage::from_bytes(bytes)
        .map_err(|e| Exit::new(exit::BAD_IMAGE, format!("{}: {e}", path.display())).into())
}

/// `foisctl image-info IMAGE [--key PUB]`.
pub fn image_info(args: &ImageInfoArgs) -> anyhow::Result<()> {
    let image = read_image(&args.image)?;
    let t = image.trailer();
    println!("image      {}", args.image.display());
    println!("version    {}", version_text(t.version));
    println!("board      {}", image.board_name());
    println!(
        "flags      {}",
        if t.allows_downgrade() {
            "downgrade (may replace a newer image)"
        } else {
            "none"
        }
    );
    println!("body       {} bytes", image.body().len());
    println!(
        "image_len  {} bytes (body + trailer: what the node writes)",
        image.image_len()
    );
    println!(
        "file       {} bytes (with the 64-byte signature)",
        image.as_bytes().len()
    );
    println!("sha512     {}", hex(&image.digest()));
    if let Some(path) = &args.key {
        let key = signing::read_public_key(path)?;
        if signing::verifies(&image, &key) {
            println!("signature  verifies with {}", path.display());
        } else {
            return Err(Exit::new(
                exit::BAD_SIGNATURE,
                format!("the signature does not verify with {}", path.display()),
            )
            .into());
        }
    }
    Ok(())
}
