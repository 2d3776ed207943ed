//! Every command in the `sh` blocks of the README and of every page of the book
//! (`docs/book/src/*.md`, with the files its `{{#include ...}}` lines name put in) runs as printed
//! (with this build's binary first on `PATH`), except the few listed in [`EXEMPT`] with the
//! reason. A plain block right after the marker `<!-- output of the command above -->` must be
//! exactly what the command before it prints on stdout.
//!
//! Each page's commands run in order in a scratch folder of their own that links the
//! repository's `examples`, `specs`, `tests` and `telegraf` folders, so files they write
//! (`out.lp`, `report/`, `target/...`) land there.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::support::BIN;

/// Commands not run here, by their start, and why.
const EXEMPT: &[(&str, &str)] = &[
    (
        "make run",
        "builds the release binary: tests/cli/first_hour.rs checks what it prints",
    ),
    ("make test", "the test command this test runs under"),
    ("sudo apt-get", "installs system packages (root, network)"),
    (
        "sudo install -d",
        "makes a folder under /var/lib (root); tests rewrite the --state folder",
    ),
    ("influx ", "needs a running InfluxDB server"),
    (
        "mosquitto_sub",
        "needs a running MQTT broker and waits for messages",
    ),
    (
        "tessla-telegraf replay",
        "needs a running MQTT broker (tests/servers/pipeline_replay.rs)",
    ),
    (
        "tessla-telegraf simulate --broker",
        "needs a running MQTT broker (tests/servers/simulate_mqtt.rs)",
    ),
    (
        "telegraf ",
        "runs Telegraf on a shipped conf (tests/servers/telegraf_real.rs runs every one under the real Telegraf)",
    ),
    (
        "tessla-telegraf run --instance-by topic --state /var/lib",
        "writes a state file into /var/lib (tests/execd/execd_state.rs)",
    ),
    (
        "sudo dpkg",
        "installs a package (root): .ci/run installs the .deb",
    ),
    (
        "make deb",
        "needs cargo-deb and a release build: .ci/run builds the .deb",
    ),
    ("cargo install", "downloads and builds a tool"),
    (
        "bash examples/fleet-one-machine/start.sh",
        "starts nats-server and four Telegrafs (tests/servers/fleet_one_machine.rs runs it)",
    ),
];

/// Commands not run here, by a part of them, and why.
const EXEMPT_CONTAINING: &[(&str, &str)] = &[(
    "--state 'nats://",
    "needs a running NATS server (tests/servers/fleet_level_nats.rs and fleet_nats*.rs run these)",
)];

/// One command of an `sh` block, and the output shown for it, if any.
struct Cmd {
    line: usize,
    text: String,
    expected: Option<String>,
}

fn readme_commands(readme: &str) -> Vec<Cmd> {
    let mut out: Vec<Cmd> = Vec::new();
    let lines: Vec<&str> = readme.lines().collect();
    let mut i = 0;
    let mut marker = false;
    while let Some(line) = lines.get(i) {
        if line.trim() == "<!-- output of the command above -->" {
            marker = true;
        } else if line.trim_start().starts_with("```") {
            let sh = line.trim() == "```sh";
            let start = i + 1;
            let mut end = start;
            while lines
                .get(end)
                .is_some_and(|l| !l.trim_start().starts_with("```"))
            {
                end += 1;
            }
            let body = lines.get(start..end).unwrap_or_default();
            if sh {
                // A line ending in `\` goes on on the next one, as in the reader's shell.
                let mut pending: Option<(usize, String)> = None;
                for (k, l) in body.iter().enumerate() {
                    let text = l.trim();
                    let (line, mut joined) = match pending.take() {
                        Some((line, head)) => (line, format!("{head} {text}")),
                        None if text.is_empty() || text.starts_with('#') => continue,
                        None => (start + k + 1, text.to_string()),
                    };
                    if let Some(head) = joined.strip_suffix('\\') {
                        joined = head.trim_end().to_string();
                        pending = Some((line, joined));
                        continue;
                    }
                    out.push(Cmd {
                        line,
                        text: joined,
                        expected: None,
                    });
                }
            } else if marker && let Some(last) = out.last_mut() {
                let mut text = body.join("\n");
                text.push('\n');
                last.expected = Some(text);
            }
            marker = false;
            i = end;
        }
        i += 1;
    }
    out
}

fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for name in ["examples", "specs", "tests", "telegraf"] {
        std::os::unix::fs::symlink(root.join(name), dir.path().join(name)).expect("link");
    }
    std::fs::create_dir_all(dir.path().join("target")).expect("target");
    dir
}

fn run(cmd: &str, dir: &Path) -> (Option<i32>, String, String) {
    let bin_dir: PathBuf = Path::new(BIN)
        .parent()
        .expect("binary folder")
        .to_path_buf();
    let path = format!(
        "{}:{}",
        bin_dir.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut child = Command::new("bash")
        .arg("-c")
        .arg(format!("set -eo pipefail; {cmd}"))
        .current_dir(dir)
        .env("PATH", path)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn bash");
    let start = Instant::now();
    loop {
        if let Ok(Some(_)) = child.try_wait() {
            break;
        }
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("command did not end within 120 s: {cmd}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().expect("output");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The README and the book's pages (sorted by name), each with its `{{#include PATH}}` lines
/// replaced by the file they name (PATH relative to the page, as mdBook reads it).
pub fn documents() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = vec![(
        "README.md".to_string(),
        std::fs::read_to_string(root.join("README.md")).expect("README.md"),
    )];
    let src = root.join("docs/book/src");
    let mut pages: Vec<PathBuf> = std::fs::read_dir(&src)
        .expect("docs/book/src")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    pages.sort();
    for page in pages {
        let text = std::fs::read_to_string(&page).expect("a book page");
        let mut full = String::new();
        for line in text.lines() {
            match line
                .trim()
                .strip_prefix("{{#include ")
                .and_then(|r| r.strip_suffix("}}"))
            {
                Some(path) => {
                    let included = src.join(path.trim());
                    let body = std::fs::read_to_string(&included).unwrap_or_else(|e| {
                        panic!("{}: include {}: {e}", page.display(), included.display())
                    });
                    full.push_str(&body);
                }
                None => {
                    full.push_str(line);
                    full.push('\n');
                }
            }
        }
        let name = format!(
            "docs/book/src/{}",
            page.file_name().unwrap_or_default().to_string_lossy()
        );
        out.push((name, full));
    }
    out
}

#[test]
fn every_command_of_the_readme_and_the_book_runs_as_printed() {
    let docs = documents();
    assert!(docs.len() >= 15, "found only {} pages", docs.len());
    let (mut all, mut ran, mut compared) = (Vec::new(), 0, 0);
    for (name, text) in &docs {
        let cmds = readme_commands(text);
        if cmds.is_empty() {
            continue;
        }
        let dir = scratch();
        for cmd in &cmds {
            let exempt = EXEMPT
                .iter()
                .find(|(start, _)| cmd.text.starts_with(start))
                .or_else(|| {
                    EXEMPT_CONTAINING
                        .iter()
                        .find(|(part, _)| cmd.text.contains(part))
                });
            if let Some((_, why)) = exempt {
                eprintln!("{name} line {}: not run ({why}): {}", cmd.line, cmd.text);
                continue;
            }
            let (code, stdout, stderr) = run(&cmd.text, dir.path());
            assert_eq!(
                code,
                Some(0),
                "{name} line {}: `{}` failed:\n{stderr}",
                cmd.line,
                cmd.text
            );
            ran += 1;
            if let Some(expected) = &cmd.expected {
                assert_eq!(
                    &stdout, expected,
                    "{name} line {}: `{}` prints something else than the page shows \
                     (`make readme-run` rewrites the shown outputs)",
                    cmd.line, cmd.text
                );
                compared += 1;
            }
        }
        all.extend(cmds);
    }
    assert!(all.len() >= 15, "found only {} commands", all.len());
    assert!(ran >= 10, "ran only {ran} commands");
    assert!(compared >= 3, "compared only {compared} outputs");
    // Every exemption is still used: a stale one would hide nothing but mislead.
    for (start, _) in EXEMPT {
        assert!(
            all.iter().any(|c| c.text.starts_with(start)),
            "exemption `{start}` matches no command of the README or the book"
        );
    }
}
