//! Compiles `proto/` with protox (pure Rust, no system protoc), generates prost code, and
//! writes the FileDescriptorSet bytes that MCAP schema records carry. Also captures the
//! build identity (rustc, target, profile, git commit) recorded in every run.
use std::{env, fs, path::PathBuf, process::Command};

const PROTOS: &[&str] = &["mps/v1/mps.proto", "foxglove/PointCloud.proto"];

fn main() {
    let out_dir = PathBuf::from(env::var("OUT_DIR").expect("OUT_DIR"));
    println!("cargo:rerun-if-changed=proto");

    let mut compiler = protox::Compiler::new(["proto"]).expect("protox compiler");
    compiler.include_imports(true).include_source_info(false);
    compiler.open_files(PROTOS).expect("compile proto/");
    let fds = compiler.file_descriptor_set();
    // Compact descriptor set (imports included, no source info): what MCAP schemas need.
    let bytes = prost::Message::encode_to_vec(&fds);
    fs::write(out_dir.join("descriptors.bin"), &bytes).expect("write descriptors.bin");
    prost_build::Config::new()
        .btree_map(["."])
        .compile_fds(fds)
        .expect("prost-build");

    let rustc = env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let rustc_version = Command::new(rustc)
        .arg("-V")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    // GIT_OPTIONAL_LOCKS=0: `git status` then does not refresh .git/index, which this script
    // watches (it would rerun, and the crate rebuild, on every build).
    let git = |args: &[&str]| {
        let mut c = Command::new("git");
        c.args(args).env("GIT_OPTIONAL_LOCKS", "0");
        c
    };
    let git_commit = git(&["rev-parse", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .unwrap_or_default();
    let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| !o.stdout.is_empty())
        .unwrap_or(false);
    println!("cargo:rustc-env=MPS_BUILD_RUSTC={rustc_version}");
    println!(
        "cargo:rustc-env=MPS_BUILD_TARGET={}",
        env::var("TARGET").unwrap_or_default()
    );
    println!(
        "cargo:rustc-env=MPS_BUILD_PROFILE={}",
        env::var("PROFILE").unwrap_or_default()
    );
    println!(
        "cargo:rustc-env=MPS_BUILD_GIT_COMMIT={}{}",
        git_commit,
        if dirty && !git_commit.is_empty() {
            "-dirty"
        } else {
            ""
        }
    );
    // The commit: HEAD names the branch, whose ref file (or packed-refs) holds it. Dirty or
    // not: the sources. Not .git/index, which any `git status` rewrites (every build after
    // one would rebuild the crate).
    // (A path that does not exist would rerun it every time: packed-refs only when there.)
    for watched in [
        ".git/HEAD",
        ".git/packed-refs",
        "src",
        "Cargo.toml",
        "Cargo.lock",
        "build.rs",
    ] {
        if std::path::Path::new(watched).exists() {
            println!("cargo:rerun-if-changed={watched}");
        }
    }
    if let Ok(head) = fs::read_to_string(".git/HEAD")
        && let Some(branch) = head.trim().strip_prefix("ref: ")
        && std::path::Path::new(".git").join(branch).exists()
    {
        println!("cargo:rerun-if-changed=.git/{branch}");
    }
}
