//! TLS for a page served beyond loopback: a certificate given (PEM files), or a self-signed one
//! made on first start in a folder and kept, with its SHA-256 fingerprint for the operator to
//! compare with what the browser shows before accepting it.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustls::ServerConfig;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

/// The self-signed certificate's file in its folder.
pub const SELF_SIGNED_CERT: &str = "web-cert.pem";
/// Its key's file (mode 0600).
pub const SELF_SIGNED_KEY: &str = "web-key.pem";

/// Why TLS could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// A file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file could not be written.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// No certificate in the file.
    #[error("{path}: no PEM certificate in it ({reason})")]
    NoCertificate {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        reason: String,
    },
    /// No private key in the file.
    #[error("{path}: no PEM private key in it ({reason})")]
    NoKey {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        reason: String,
    },
    /// The certificate could not be made.
    #[error("making a self-signed certificate: {0}")]
    Generate(String),
    /// The certificate and key do not go together.
    #[error("the certificate and key do not make a TLS configuration: {0}")]
    Config(#[from] rustls::Error),
}

/// A server's TLS: its configuration and its certificate's fingerprint.
#[derive(Debug, Clone)]
pub struct Tls {
    /// For each connection.
    pub config: Arc<ServerConfig>,
    /// SHA-256 of the (first) certificate, `AB:CD:...`.
    pub fingerprint: String,
    /// The certificate was made just now.
    pub made: bool,
}

fn read(path: &Path) -> Result<Vec<u8>, TlsError> {
    std::fs::read(path).map_err(|source| TlsError::Read {
        path: path.to_owned(),
        source,
    })
}

/// TLS with the certificate chain in `cert` and the key in `key` (PEM).
pub fn from_files(cert: &Path, key: &Path) -> Result<Tls, TlsError> {
    let chain = CertificateDer::pem_slice_iter(&read(cert)?)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|error| TlsError::NoCertificate {
            path: cert.to_owned(),
            reason: error.to_string(),
        })?;
    if chain.is_empty() {
        return Err(TlsError::NoCertificate {
            path: cert.to_owned(),
            reason: "the file holds none".into(),
        });
    }
    let private = PrivateKeyDer::from_pem_slice(&read(key)?).map_err(|error| TlsError::NoKey {
        path: key.to_owned(),
        reason: error.to_string(),
    })?;
    let fingerprint = fingerprint(&chain[0]);
    Ok(Tls {
        config: config(chain, private)?,
        fingerprint,
        made: false,
    })
}

/// TLS with the self-signed certificate kept in `dir`, made there first (for `names`: the host
/// names and addresses the page is reached by) when it is not there yet.
pub fn self_signed(dir: &Path, names: &[String]) -> Result<Tls, TlsError> {
    let (cert, key) = (dir.join(SELF_SIGNED_CERT), dir.join(SELF_SIGNED_KEY));
    if cert.exists() && key.exists() {
        return from_files(&cert, &key);
    }
    let made = rcgen::generate_simple_self_signed(names.to_vec())
        .map_err(|error| TlsError::Generate(error.to_string()))?;
    let write = |path: &Path, text: &str, mode: u32| {
        use std::io::Write;
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::create_dir_all(dir)
            .and_then(|()| {
                std::fs::OpenOptions::new()
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .mode(mode)
                    .open(path)
            })
            .and_then(|mut file| file.write_all(text.as_bytes()))
            .map_err(|source| TlsError::Write {
                path: path.to_owned(),
                source,
            })
    };
    write(&key, &made.signing_key.serialize_pem(), 0o600)?;
    write(&cert, &made.cert.pem(), 0o644)?;
    let mut tls = from_files(&cert, &key)?;
    tls.made = true;
    Ok(tls)
}

/// SHA-256 of `der`, as browsers show it: `AB:CD:...`.
pub fn fingerprint(der: &[u8]) -> String {
    ring::digest::digest(&ring::digest::SHA256, der)
        .as_ref()
        .iter()
        .map(|byte| format!("{byte:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

fn config(
    chain: Vec<CertificateDer<'static>>,
    key: PrivateKeyDer<'static>,
) -> Result<Arc<ServerConfig>, TlsError> {
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let config = ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()?
        .with_no_client_auth()
        .with_single_cert(chain, key)?;
    Ok(Arc::new(config))
}

/// TLS that cannot be set up is a usage error: the files or the flags are wrong.
impl scout_interface::failure::FailureKind for TlsError {
    fn kind(&self) -> scout_interface::failure::Failure {
        scout_interface::failure::Failure::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_self_signed_certificate_is_made_once_kept_and_its_key_private() {
        let dir = std::env::temp_dir().join(format!("scout-web-tls-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let first = self_signed(&dir, &["localhost".into(), "127.0.0.1".into()]).expect("made");
        assert!(first.made);
        assert_eq!(first.fingerprint.len(), 32 * 3 - 1);
        let again = self_signed(&dir, &["other".into()]).expect("read back");
        assert!(!again.made);
        assert_eq!(again.fingerprint, first.fingerprint, "the same certificate");
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(dir.join(SELF_SIGNED_KEY))
            .expect("key")
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "the key is its owner's alone: {mode:o}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn files_without_a_certificate_or_key_are_named() {
        let dir = std::env::temp_dir().join(format!("scout-web-tls-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let empty = dir.join("empty.pem");
        std::fs::write(&empty, "nothing here\n").expect("write");
        let error = from_files(&empty, &empty).expect_err("no certificate");
        assert!(error.to_string().contains("empty.pem"), "{error}");
        let missing = from_files(&dir.join("absent.pem"), &empty).expect_err("missing");
        assert!(matches!(missing, TlsError::Read { .. }), "{missing}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
