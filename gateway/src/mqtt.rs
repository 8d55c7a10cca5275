//! Connection set-up for rumqttc: the client options (client id,
//! credentials, keep-alive, the last will, packet limits), the rustls
//! client config (ring provider) from PEM files, and words for a
//! connection error that say what is wrong.

use std::sync::Arc;

use anyhow::Context;
use rumqttc::{
    ConnectionError, LastWill, MqttOptions, QoS, StateError, TlsConfiguration, Transport,
};

use crate::config::{BrokerConfig, TlsConfig};
use crate::topics::Topics;

/// The client's packet-id space, larger than the records the gateway keeps
/// in flight (see [`crate::inflight`]).
pub const INFLIGHT: u16 = 1024;

/// The largest packet the gateway accepts from the broker: MQTT's own
/// limit (a remaining length of 2²⁸ − 1). A smaller limit would make
/// rumqttc drop the connection when any client publishes a big message on
/// a command topic (a retained one: at every reconnection); the gateway
/// instead reads it and skips it ([`crate::command::MAX_COMMAND_BYTES`]).
/// Brokers bound what they accept themselves (Mosquitto:
/// `message_size_limit`).
pub const MAX_INCOMING_PACKET: usize = 268_435_455 + 5;

/// The largest packet the gateway sends (a queue record is at most 1 MiB).
pub const MAX_OUTGOING_PACKET: usize = 1024 * 1024;

/// The client options: credentials, the last will (`offline`, retained, on
/// the gateway's availability topic), TLS.
pub fn mqtt_options(b: &BrokerConfig, topics: &Topics) -> anyhow::Result<MqttOptions> {
    let mut o = MqttOptions::new(b.client_id.clone(), b.host.clone(), b.port);
    o.set_keep_alive(b.keep_alive);
    o.set_clean_session(true);
    o.set_inflight(INFLIGHT);
    o.set_max_packet_size(MAX_INCOMING_PACKET, MAX_OUTGOING_PACKET);
    o.set_last_will(LastWill::new(
        topics.gateway_availability(),
        "offline",
        QoS::AtLeastOnce,
        true,
    ));
    if let Some(u) = &b.username {
        let pw = b.password.as_ref().map(|p| p.expose()).unwrap_or("");
        o.set_credentials(u.clone(), pw);
    }
    if let Some(t) = &b.tls {
        let cfg = rustls_config(t)?;
        o.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
            Arc::new(cfg),
        )));
    }
    Ok(o)
}

/// A rustls client config (ring provider) from PEM files.
pub fn rustls_config(t: &TlsConfig) -> anyhow::Result<rustls::ClientConfig> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut roots = rustls::RootCertStore::empty();
    let ca = &t.ca_file;
    for cert in CertificateDer::pem_file_iter(ca)
        .with_context(|| format!("cannot read the CA file {}", ca.display()))?
    {
        let cert = cert.with_context(|| format!("the CA file {} is not PEM", ca.display()))?;
        roots
            .add(cert)
            .with_context(|| format!("a certificate in {} is not usable", ca.display()))?;
    }
    if roots.is_empty() {
        anyhow::bail!("the CA file {} holds no certificate", ca.display());
    }
    let builder = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .context("TLS set-up")?
        .with_root_certificates(roots);
    Ok(match &t.client_auth {
        None => builder.with_no_client_auth(),
        Some((cert, key)) => {
            let certs = CertificateDer::pem_file_iter(cert)
                .with_context(|| format!("cannot read the client certificate {}", cert.display()))?
                .collect::<Result<Vec<_>, _>>()
                .with_context(|| format!("the client certificate {} is not PEM", cert.display()))?;
            if certs.is_empty() {
                anyhow::bail!("{} holds no certificate", cert.display());
            }
            let key = PrivateKeyDer::from_pem_file(key)
                .with_context(|| format!("cannot read the client key {}", key.display()))?;
            builder
                .with_client_auth_cert(certs, key)
                .context("the client certificate and key do not match")?
        }
    })
}

/// Words for a connection error that say what is wrong (no secrets: the
/// client never puts the password in its errors).
pub fn describe(e: &ConnectionError) -> String {
    const NOT_MQTT: &str =
        "is this the broker's MQTT port, with TLS on or off as the broker expects?";
    match e {
        ConnectionError::ConnectionRefused(code) => format!("the broker refused: {code:?}"),
        ConnectionError::NotConnAck(p) => format!(
            "the server did not answer as an MQTT broker (its first packet was {} instead of \
             CONNACK): {NOT_MQTT}",
            packet_name(p)
        ),
        ConnectionError::MqttState(StateError::Deserialization(d)) => {
            format!("the server sent bytes that are not MQTT ({d}): {NOT_MQTT}")
        }
        ConnectionError::Io(io) => format!("{io}"),
        other => other.to_string(),
    }
}

fn packet_name(p: &rumqttc::Packet) -> &'static str {
    use rumqttc::Packet;
    match p {
        Packet::Connect(_) => "CONNECT",
        Packet::ConnAck(_) => "CONNACK",
        Packet::Publish(_) => "PUBLISH",
        Packet::PubAck(_) => "PUBACK",
        Packet::PubRec(_) => "PUBREC",
        Packet::PubRel(_) => "PUBREL",
        Packet::PubComp(_) => "PUBCOMP",
        Packet::Subscribe(_) => "SUBSCRIBE",
        Packet::SubAck(_) => "SUBACK",
        Packet::Unsubscribe(_) => "UNSUBSCRIBE",
        Packet::UnsubAck(_) => "UNSUBACK",
        Packet::PingReq => "PINGREQ",
        Packet::PingResp => "PINGRESP",
        Packet::Disconnect => "DISCONNECT",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_mqtt_answer_is_named_as_such() {
        let e = ConnectionError::NotConnAck(rumqttc::Packet::PubAck(rumqttc::PubAck::new(3)));
        let text = describe(&e);
        assert!(text.contains("not answer as an MQTT broker"), "{text}");
        assert!(text.contains("PUBACK instead of CONNACK"), "{text}");
        assert!(!text.contains("Expected ConnAck"), "{text}");
    }
}
