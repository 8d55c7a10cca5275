//! `foisctl config get|set`: read the node's config, or change fields
//! checked on the host with the node's own rule before anything is sent.

use clap::{Args, Subcommand};
use fois_protocol::{AckResult, Command, Config, ConfigError, ConfigV1, FIELDS};

use super::request::{RequestArgs, ack_result, expect_ack};
use crate::exit::{self, Exit};
use fois_link::Reply;

/// `foisctl config`.
#[derive(Debug, Args)]
pub struct ConfigArgs {
    /// `get` or `set`.
    #[command(subcommand)]
    pub cmd: ConfigCmd,
}

/// `config get` / `config set`.
#[derive(Debug, Subcommand)]
pub enum ConfigCmd {
    /// Print every config field with its value, unit and allowed range.
    #[command(after_help = exit::TABLE)]
    Get(RequestArgs),
    /// Change fields: KEY=VALUE ... (integers in the field's unit, see `config
    /// get`). Checked on the host with the node's own rule before sending.
    #[command(after_help = exit::TABLE)]
    Set {
        /// The port and the answer timeout.
        #[command(flatten)]
        args: RequestArgs,
        /// KEY=VALUE pairs, e.g. onset_rise_na=1500 frame_period_ms=200.
        #[arg(value_name = "KEY=VALUE", required = true)]
        pairs: Vec<String>,
    },
}

/// Run `foisctl config ...`.
pub fn run(args: ConfigArgs) -> anyhow::Result<()> {
    match args.cmd {
        ConfigCmd::Get(a) => config_get(&a).map(|_| ()),
        ConfigCmd::Set { args, pairs } => config_set(&args, &pairs).map(|_| ()),
    }
}

/// A parsed `KEY=VALUE`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Assignment {
    /// The key.
    pub key: String,
    /// The value text.
    pub value: String,
}

/// Parse `KEY=VALUE` strings and check each value against its field's
/// range (cross-field rules are checked once the node's config is known).
pub fn parse_assignments(args: &[String]) -> Result<Vec<Assignment>, Exit> {
    if args.is_empty() {
        return Err(Exit::new(
            exit::INVALID_VALUE,
            "config set needs at least one KEY=VALUE",
        ));
    }
    let mut out: Vec<Assignment> = Vec::new();
    for a in args {
        let Some((k, v)) = a.split_once('=') else {
            return Err(Exit::new(
                exit::INVALID_VALUE,
                format!("`{a}` is not KEY=VALUE (keys: {})", keys()),
            ));
        };
        let mut probe = Config::default();
        probe
            .set_from_str(k, v)
            .map_err(|e| refused(&format!("{k}={v}"), e))?;
        if let Some(first) = out.iter().find(|o| o.key == k.trim()) {
            return Err(Exit::new(
                exit::INVALID_VALUE,
                format!(
                    "refused on the host, nothing sent: {} is given twice ({}={} and {a}): give each key once",
                    first.key, first.key, first.value
                ),
            ));
        }
        out.push(Assignment {
            key: k.trim().to_string(),
            value: v.trim().to_string(),
        });
    }
    Ok(out)
}

fn keys() -> String {
    FIELDS.iter().map(|f| f.name).collect::<Vec<_>>().join(", ")
}

fn refused(what: &str, e: ConfigError) -> Exit {
    let extra = match e {
        ConfigError::UnknownField => format!(" (keys: {})", keys()),
        ConfigError::BelowMin(f) | ConfigError::AboveMax(f) => {
            let s = f.spec();
            format!(" (allowed {}..={} {})", s.min, s.max, s.unit)
        }
        _ => String::new(),
    };
    Exit::new(
        exit::INVALID_VALUE,
        format!("refused on the host, nothing sent: {what}: {e}{extra}"),
    )
}

/// Apply assignments to `base` and run the node's own rule on the result.
pub fn apply(base: &Config, sets: &[Assignment]) -> Result<Config, Exit> {
    let mut c = base.clone();
    for a in sets {
        c.set_from_str(&a.key, &a.value)
            .map_err(|e| refused(&format!("{}={}", a.key, a.value), e))?;
    }
    c.validate()
        .map_err(|e| refused("the resulting config", e))?;
    Ok(c)
}

/// The config a node holds, in the shape its protocol version carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NodeConfig {
    /// A version-1/2 node: the twelve fields of [`ConfigV1`].
    V1(ConfigV1),
    /// A version-3 node: every field.
    V3(Config),
}

impl NodeConfig {
    /// The config with every field (a version-1/2 node's newer fields at
    /// their defaults: it has none).
    pub fn full(&self) -> Config {
        match self {
            NodeConfig::V1(c) => Config::from(c.clone()),
            NodeConfig::V3(c) => c.clone(),
        }
    }

    /// The newest protocol version whose config fields this node holds.
    pub fn fields_version(&self) -> u16 {
        match self {
            NodeConfig::V1(_) => 1,
            NodeConfig::V3(_) => 3,
        }
    }

    /// The config of the node's answer to `GetConfig` or `SetConfig*`.
    pub fn from_ack(result: &AckResult) -> Option<NodeConfig> {
        match result {
            AckResult::Config(c) => Some(NodeConfig::V1(c.clone())),
            AckResult::ConfigV3(c) => Some(NodeConfig::V3(c.clone())),
            _ => None,
        }
    }

    /// The command that sets `wanted` on this node, in its version's shape.
    pub fn set_command(&self, wanted: &Config) -> Command {
        match self {
            NodeConfig::V1(_) => Command::SetConfig(ConfigV1::from(wanted)),
            NodeConfig::V3(_) => Command::SetConfigV3(wanted.clone()),
        }
    }
}

/// The config as a table: key, value, unit, range, meaning; only the fields
/// a node of protocol `fields_version` has.
pub fn config_table(c: &Config, fields_version: u16) -> String {
    let mut s = String::new();
    for f in FIELDS.iter().filter(|f| f.since_version <= fields_version) {
        s.push_str(&format!(
            "{:<24} {:>8} {:<8} [{}..={}]  {}\n",
            f.name,
            c.get(f.field),
            f.unit,
            f.min,
            f.max,
            f.doc
        ));
    }
    s
}

fn get(
    link: &mut fois_link::Link<Box<dyn serialport::SerialPort>>,
    t: &RequestArgs,
) -> anyhow::Result<NodeConfig> {
    let reply = link.request(Command::GetConfig, t.timeout())?;
    if let Reply::Ack(a) = &reply
        && let Some(c) = NodeConfig::from_ack(&a.result)
    {
        return Ok(c);
    }
    expect_ack(reply)?;
    Err(Exit::new(
        exit::FAILURE,
        "the node answered GetConfig with something else",
    )
    .into())
}

/// `config get`: print the node's config.
pub fn config_get(t: &RequestArgs) -> anyhow::Result<Config> {
    let mut link = t.connect()?;
    let c = get(&mut link, t)?;
    print!("{}", config_table(&c.full(), c.fields_version()));
    Ok(c.full())
}

/// Refuse keys the node's protocol version does not have, before sending.
pub fn check_keys_for(node: &NodeConfig, sets: &[Assignment]) -> Result<(), Exit> {
    let version = node.fields_version();
    for a in sets {
        if let Some(field) = fois_protocol::ConfigField::from_name(&a.key)
            && field.spec().since_version > version
        {
            return Err(Exit::new(
                exit::INVALID_VALUE,
                format!(
                    "refused on the host, nothing sent: {} needs a node of protocol version {} \
                     or newer (this node's config has the version-{version} fields; update its firmware)",
                    a.key,
                    field.spec().since_version
                ),
            ));
        }
    }
    Ok(())
}

/// What a `config set` that changes nothing says: `onset_frames is already 20`.
pub fn unchanged(sets: &[Assignment]) -> String {
    let what: Vec<String> = sets
        .iter()
        .map(|a| format!("{} is already {}", a.key, a.value))
        .collect();
    format!("no change: {}", what.join(", "))
}

/// `config set`: check on the host, send (only if something changes),
/// print what the node now uses (`key: old -> new unit`).
pub fn config_set(t: &RequestArgs, args: &[String]) -> anyhow::Result<Config> {
    let sets = parse_assignments(args)?;
    let mut link = t.connect()?;
    let node = get(&mut link, t)?;
    check_keys_for(&node, &sets)?;
    let current = node.full();
    let wanted = apply(&current, &sets)?;
    if wanted == current {
        println!("{}; nothing sent, nothing written", unchanged(&sets));
        return Ok(current);
    }
    let reply = link.request(node.set_command(&wanted), t.timeout())?;
    let result = ack_result(reply)?;
    let Some(now) = NodeConfig::from_ack(&result) else {
        return Err(Exit::new(exit::FAILURE, "unexpected answer to SetConfig").into());
    };
    let now = now.full();
    for f in FIELDS
        .iter()
        .filter(|f| f.since_version <= node.fields_version())
    {
        let (a, b) = (current.get(f.field), now.get(f.field));
        if a != b {
            println!("{}: {a} -> {b} {}", f.name, f.unit);
        }
    }
    if now != wanted {
        return Err(Exit::new(exit::REFUSED, "the node's config differs from the one sent").into());
    }
    Ok(now)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn host_refuses_bad_assignments_with_code_7() {
        for bad in [
            &["nonsense"][..],
            &["nope=1"],
            &["settle_us=abc"],
            &["settle_us=1"],
            &["load_r1_ohm=2000000"],
            &[],
        ] {
            let e = parse_assignments(&s(bad)).unwrap_err();
            assert_eq!(e.code, exit::INVALID_VALUE, "{bad:?}");
        }
        let e = parse_assignments(&s(&["settle_us=1"])).unwrap_err();
        assert!(e.message.contains("20..=5000"), "{}", e.message);
    }

    #[test]
    fn a_key_given_twice_is_refused_by_name() {
        let e = parse_assignments(&s(&["onset_frames=20", "settle_us=100", "onset_frames=30"]))
            .unwrap_err();
        assert_eq!(e.code, exit::INVALID_VALUE);
        assert!(
            e.message.contains("onset_frames is given twice")
                && e.message.contains("onset_frames=20 and onset_frames=30"),
            "{}",
            e.message
        );
    }

    #[test]
    fn a_set_that_changes_nothing_is_recognised() {
        let c = Config::default();
        let same = format!("onset_frames={}", c.onset_frames);
        let sets = parse_assignments(&s(&[&same])).unwrap();
        assert_eq!(apply(&c, &sets).unwrap(), c);
        assert_eq!(
            unchanged(&sets),
            format!("no change: onset_frames is already {}", c.onset_frames)
        );
    }

    #[test]
    fn cross_field_rule_is_applied_before_sending() {
        let sets = parse_assignments(&s(&["clear_rise_na=2000"])).unwrap();
        let e = apply(&Config::default(), &sets).unwrap_err();
        assert!(e.message.contains("below onset"), "{}", e.message);
        let sets = parse_assignments(&s(&["onset_rise_na=3000", "clear_rise_na=2000"])).unwrap();
        let c = apply(&Config::default(), &sets).unwrap();
        assert_eq!((c.onset_rise_na, c.clear_rise_na), (3000, 2000));
    }

    #[test]
    fn an_older_node_gets_the_old_shape_and_no_gain_keys() {
        let old = NodeConfig::V1(ConfigV1::from(&Config::default()));
        let new = NodeConfig::V3(Config::default());
        let sets = parse_assignments(&s(&["gain_tempco_ppm_per_k=-3000"])).unwrap();
        let e = check_keys_for(&old, &sets).unwrap_err();
        assert_eq!(e.code, exit::INVALID_VALUE);
        assert!(e.message.contains("protocol version 3"), "{}", e.message);
        assert!(check_keys_for(&new, &sets).is_ok());
        let wanted = apply(&new.full(), &sets).unwrap();
        assert_eq!(wanted.gain_tempco_ppm_per_k, -3_000);
        assert!(matches!(old.set_command(&wanted), Command::SetConfig(_)));
        assert_eq!(
            new.set_command(&wanted),
            Command::SetConfigV3(wanted.clone())
        );
        // The table of an older node shows its twelve fields only.
        assert_eq!(config_table(&old.full(), 1).lines().count(), 12);
        assert_eq!(config_table(&new.full(), 3).lines().count(), 16);
    }
}
