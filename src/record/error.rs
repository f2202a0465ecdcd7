use std::path::PathBuf;

/// Errors while writing or reading a run file. Every variant names the file concerned.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: MCAP: {source}", path.display())]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    #[error("{}: cannot decode {what}: {source}", path.display())]
    Decode {
        path: PathBuf,
        what: String,
        #[source]
        source: prost::DecodeError,
    },
    #[error("{}: not a valid run file: {reason}", path.display())]
    Invalid { path: PathBuf, reason: String },
    /// The run's file exists already (a finished run of the same experiment) and replacing it
    /// was not asked for.
    #[error("{} already exists: a finished run of this same experiment", path.display())]
    Exists { path: PathBuf },
    /// Another process holds the lock on the `.partial` file: it is writing this run now.
    #[error("another runner is writing {} now (the file is locked)", path.display())]
    Busy { path: PathBuf },
    /// A `.partial` file no process holds: a killed run's, with its checkpoints.
    #[error("{} holds an unfinished run (killed, or stopped by a crash)", path.display())]
    Unfinished { path: PathBuf },
    /// A finished file (it ends with the MCAP footer) that is not whole: the reason names the
    /// first damaged part and its byte offset.
    #[error("{}: damaged: {reason}", path.display())]
    Damaged { path: PathBuf, reason: String },
}

impl RecordError {
    /// True for the refusals to start writing (the file exists, is being written, or holds an
    /// unfinished run): nothing was written.
    pub fn is_refusal(&self) -> bool {
        matches!(
            self,
            RecordError::Exists { .. } | RecordError::Busy { .. } | RecordError::Unfinished { .. }
        )
    }
}

pub type Result<T, E = RecordError> = std::result::Result<T, E>;

pub(crate) fn io_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> RecordError + '_ {
    move |source| RecordError::Io {
        path: path.to_path_buf(),
        source,
    }
}

pub(crate) fn mcap_err(path: &std::path::Path) -> impl FnOnce(mcap::McapError) -> RecordError + '_ {
    move |source| RecordError::Mcap {
        path: path.to_path_buf(),
        source,
    }
}
