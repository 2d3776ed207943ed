//! Secrets a state store logs in with (password, token): a [`Secret`] is never shown, not even
//! by `{:?}`, and a [`SecretSource`] reads one from the URL, an environment variable or a file
//! (the last two keep it out of `ps` and of Telegraf's config).

/// A secret (password, token, NKey seed): never shown, also not by `{:?}`.
#[derive(Clone, PartialEq)]
pub struct Secret(String);

impl Secret {
    pub fn new(s: impl Into<String>) -> Secret {
        Secret(s.into())
    }

    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("***")
    }
}

/// Why a secret could not be read: the message names the variable or file, never the value.
#[derive(Debug, thiserror::Error)]
pub enum SecretError {
    #[error(
        "the {what} is to come from environment variable {var}, which is not set (or not UTF-8)"
    )]
    Unset { what: String, var: String },
    #[error("cannot read the {what} from {}: {source}", path.display())]
    Unreadable {
        what: String,
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("the {what} from {origin} is empty")]
    Empty { what: String, origin: String },
}

/// Where a secret comes from: the URL itself, an environment variable or a file (the last two
/// keep it out of `ps` and of Telegraf's config).
#[derive(Debug, Clone, PartialEq)]
pub enum SecretSource {
    Given(Secret),
    Env(String),
    File(std::path::PathBuf),
}

impl SecretSource {
    /// The secret, read now (a file's trailing newline removed). The error names the variable
    /// or file, never the value.
    pub fn read(&self, what: &str) -> Result<Secret, SecretError> {
        let value = match self {
            SecretSource::Given(s) => return Ok(s.clone()),
            SecretSource::Env(var) => std::env::var(var).map_err(|_| SecretError::Unset {
                what: what.to_string(),
                var: var.clone(),
            })?,
            SecretSource::File(path) => std::fs::read_to_string(path)
                .map_err(|source| SecretError::Unreadable {
                    what: what.to_string(),
                    path: path.clone(),
                    source,
                })?
                .trim_end_matches(['\r', '\n'])
                .to_string(),
        };
        if value.is_empty() {
            return Err(SecretError::Empty {
                what: what.to_string(),
                origin: self.origin(),
            });
        }
        Ok(Secret(value))
    }

    pub(crate) fn origin(&self) -> String {
        match self {
            SecretSource::Given(_) => "the URL".into(),
            SecretSource::Env(v) => format!("environment variable {v}"),
            SecretSource::File(p) => p.display().to_string(),
        }
    }
}
