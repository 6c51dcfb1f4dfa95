//! Generates `include/softshell.h` from the Rust sources with cbindgen (pinned in Cargo.toml).
//!
//! The header is committed. It is rewritten only when its text changes, so an unchanged build
//! leaves the file (and its timestamp) alone, and CI can fail when a build changes it
//! (`git diff --exit-code include/softshell.h`).

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=src");
    println!("cargo:rerun-if-changed=cbindgen.toml");
    println!("cargo:rerun-if-changed=build.rs");

    let crate_dir = PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let mut config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("cbindgen.toml must parse");

    // The version macros come from Cargo.toml, the same source as softshell_version_string(),
    // so the two cannot disagree.
    let major = env::var("CARGO_PKG_VERSION_MAJOR").unwrap();
    let minor = env::var("CARGO_PKG_VERSION_MINOR").unwrap();
    let patch = env::var("CARGO_PKG_VERSION_PATCH").unwrap();
    config.after_includes = Some(format!(
        "\n/* Version of the headers you compiled against; compare with softshell_version_string()\n   \
         and softshell_abi_version() at run time to detect a mismatched library. */\n\
         #define SOFTSHELL_VERSION_MAJOR {major}\n\
         #define SOFTSHELL_VERSION_MINOR {minor}\n\
         #define SOFTSHELL_VERSION_PATCH {patch}\n\
         #define SOFTSHELL_VERSION_STRING \"{major}.{minor}.{patch}\"\n\
         /* softshell_abi_version() returns this: (major << 16) | (minor << 8) | patch. */\n\
         #define SOFTSHELL_ABI_VERSION ((SOFTSHELL_VERSION_MAJOR << 16) | (SOFTSHELL_VERSION_MINOR << 8) | SOFTSHELL_VERSION_PATCH)\n"
    ));

    let bindings = match cbindgen::Builder::new().with_crate(&crate_dir).with_config(config).generate() {
        Ok(bindings) => bindings,
        Err(err) => panic!("cbindgen failed to generate include/softshell.h: {err}"),
    };

    let mut text = Vec::new();
    bindings.write(&mut text);
    let header_path = crate_dir.join("include").join("softshell.h");
    let unchanged = fs::read(&header_path).map(|old| old == text).unwrap_or(false);
    if !unchanged {
        fs::create_dir_all(header_path.parent().unwrap()).expect("create include/");
        fs::write(&header_path, &text).expect("write include/softshell.h");
    }
}
