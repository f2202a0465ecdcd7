//! Identity of the running binary, recorded in every run file (`build` metadata).
//!
//! Values come from `build.rs` (`MPS_BUILD_*`) and Cargo, fixed at compile time, so the same
//! binary always records the same build identity.

use std::fmt;

/// Compile-time identity of this build.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BuildInfo {
    /// `CARGO_PKG_VERSION` of `mps_runner`.
    pub crate_version: &'static str,
    /// `git rev-parse HEAD` at build time, with `-dirty` appended when tracked files were
    /// modified; empty when built outside a git checkout.
    pub git_commit: &'static str,
    /// `rustc -V` of the compiler that built the crate.
    pub rustc: &'static str,
    /// Target triple.
    pub target: &'static str,
    /// Cargo profile as seen by the build script (`release` or `debug`).
    pub profile: &'static str,
}

impl BuildInfo {
    /// The identity of the binary this code is linked into.
    pub fn current() -> BuildInfo {
        BuildInfo {
            crate_version: env!("CARGO_PKG_VERSION"),
            git_commit: env!("MPS_BUILD_GIT_COMMIT"),
            rustc: env!("MPS_BUILD_RUSTC"),
            target: env!("MPS_BUILD_TARGET"),
            profile: env!("MPS_BUILD_PROFILE"),
        }
    }
}

impl fmt::Display for BuildInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let commit = if self.git_commit.is_empty() {
            "unknown commit"
        } else {
            self.git_commit
        };
        write!(
            f,
            "mps_runner {} ({}; {}; {}; {})",
            self.crate_version, commit, self.profile, self.target, self.rustc
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn current_is_filled_in() {
        let b = BuildInfo::current();
        assert_eq!(b.crate_version, env!("CARGO_PKG_VERSION"));
        assert!(b.rustc.starts_with("rustc "), "{}", b.rustc);
        assert!(!b.target.is_empty());
        assert!(!b.profile.is_empty());
        let line = b.to_string();
        assert!(!line.contains('\n'));
        assert!(line.starts_with("mps_runner "));
    }
}
