//! Why a rollout (or the fleet's decision on one) cannot be used here: every reason from the
//! record's signature to the version's checks in this process ([`RolloutError`]). A process
//! reports it as its vote's reason, and `spec rollback` and `spec status` show it.

use super::sign::RecordError;
use crate::nats::conn::Failure;

/// Why a rollout or decision is refused, each reason saying which: the record ([`RecordError`]),
/// the bundle it names, where it is stored, the channel, or the version's checks here.
#[derive(Debug, Clone, thiserror::Error)]
pub enum RolloutError {
    /// Unreadable, unsigned, signed by a key not trusted, or changed after signing.
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error("it names the base version (the spec each process started with) with a digest")]
    BaseWithDigest,
    #[error("its version id {id} is not the first 12 digits of its digest {digest}")]
    IdNotOfDigest { id: String, digest: String },
    /// The bundle's key.
    #[error("its bundle {0} is not in the spec channel")]
    NoBundle(String),
    #[error("its bundle {key} cannot be read: {why}")]
    BundleUnreadable { key: String, why: String },
    #[error("its bundle {key} is not a spec bundle: {why}")]
    NotABundle { key: String, why: String },
    /// `digest`: what the bundle hashes to.
    #[error(
        "its bundle {key} does not hash to the digest the rollout was signed with (it hashes \
         to {digest}): the bundle was changed after publishing"
    )]
    BundleChanged { key: String, digest: String },
    /// A rollout stored under another revision's key.
    #[error(
        "it says it is revision {said} but is stored as {key}: a rollout copied from elsewhere"
    )]
    RolloutMoved { said: u64, key: String },
    /// A decision stored under another revision's key.
    #[error("it says it decides revision {said} but is stored as {key}")]
    DecisionMoved { said: u64, key: String },
    #[error("the spec channel has no bucket")]
    NoBucket,
    /// A key that existed a moment before.
    #[error("{0} vanished while it was read")]
    Vanished(String),
    /// The spec channel could not be read.
    #[error(transparent)]
    Channel(#[from] Failure),
    /// The run has no processor to check the version with.
    #[error("no processor")]
    NoProcessor,
    #[error("its bundle is version {bundle}, not {said} as the rollout says")]
    OtherVersion { bundle: String, said: String },
    /// The first lines of the compiler's diagnostic.
    #[error("it does not check here: {0}")]
    DoesNotCheck(String),
    #[error("it has no outputs, so it would check nothing and write nothing")]
    NoOutputs,
    /// A fleet rollout must name a published fleet spec version.
    #[error(
        "a fleet rollout names its version (publish the earlier fleet spec again with `spec publish --fleet`)"
    )]
    FleetBase,
    /// The fleet level's check of a fleet spec version (the messages of `--fleet-spec`).
    #[error("{0}")]
    FleetCheck(String),
    /// The processor's checks: selector, annotations, bindings.
    #[error(transparent)]
    Processor(#[from] crate::processor::Refusal),
}
