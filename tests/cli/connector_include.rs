//! A TeSSLa Telegraf Connector user's spec run from a directory of its own: `include
//! "./Telegraf.tessla"` (or `"Telegraf.tessla"`) with no such file beside the spec reads our
//! bundled Telegraf annotations and says so once at `I!`; a file that is there is read as
//! written; a spec using the annotations without the include is told the line to add.

use crate::support::child;

use child::{run_in, text, write};

/// The connector's CPU example, as its users write it.
const SPEC: &str = "include \"INCLUDE\"\n\
    @TelegrafIn(\"cpu\", \"\", \"usage_idle\")\n\
    in idle: Events[Float]\n\
    def busy = 100.0 -. idle\n\
    def high = busy >. 50.0\n\
    @TelegrafOut(\"cpu_high\")\n\
    out high\n";

#[test]
fn the_connectors_include_works_from_an_empty_directory() {
    for include in ["./Telegraf.tessla", "Telegraf.tessla"] {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "spec.tessla", &SPEC.replace("INCLUDE", include));
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let out = run_in(dir.path(), &["check", "spec.tessla"], b"");
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{include}: {err}");
        assert!(
            text(&out.stdout).contains("@TelegrafOut(name = \"cpu_high\")"),
            "{include}: {}",
            text(&out.stdout)
        );
        let info: Vec<&str> = err.lines().filter(|l| l.starts_with("I! ")).collect();
        assert_eq!(info.len(), 1, "{include}: {err}");
        assert!(
            info[0].contains(&format!("include \"{include}\""))
                && info[0].contains("bundled Telegraf annotations"),
            "{err}"
        );
        assert!(!err.contains("W! ") && !err.contains("warning"), "{err}");
        let out = run_in(
            dir.path(),
            &["run", "--spec", "spec.tessla", "--no-passthrough"],
            b"cpu usage_idle=20.0 1000000000\ncpu usage_idle=90.0 2000000000\n",
        );
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        assert_eq!(
            text(&out.stdout),
            "cpu_high value=true 1000000000\ncpu_high value=false 2000000000\n"
        );
        let info = text(&out.stderr)
            .lines()
            .filter(|l| l.contains("bundled Telegraf annotations"))
            .count();
        assert_eq!(info, 1, "{}", text(&out.stderr));
    }
}

#[test]
fn a_telegraf_tessla_beside_the_spec_is_used_as_written() {
    let dir = tempfile::tempdir().unwrap();
    // The connector's own file plus a definition of the user's: the spec uses both.
    write(
        dir.path(),
        "Telegraf.tessla",
        "def @TelegrafIn(measurement: String, tags: String, field: String)\n\
         def @TelegrafOut(name: String)\n\
         def limit = 50.0\n",
    );
    let spec = SPEC
        .replace("INCLUDE", "./Telegraf.tessla")
        .replace("busy >. 50.0", "busy >. limit");
    write(dir.path(), "spec.tessla", &spec);
    let out = run_in(dir.path(), &["check", "spec.tessla"], b"");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("bundled"), "{err}");
    // The bundled library has no `limit`: with it the spec would not load.
    std::fs::remove_file(dir.path().join("Telegraf.tessla")).unwrap();
    let out = run_in(dir.path(), &["check", "spec.tessla"], b"");
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("unknown name `limit`"));
}

#[test]
fn an_undeclared_telegraf_annotation_gets_the_include_line_to_add() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SPEC.replace("include \"INCLUDE\"\n", "");
    write(dir.path(), "spec.tessla", &spec);
    let out = run_in(dir.path(), &["check", "spec.tessla"], b"");
    let err = text(&out.stderr);
    assert!(
        err.contains("annotation `@TelegrafIn` is not declared"),
        "{err}"
    );
    assert!(
        err.contains("help: add this line at the top of the spec: include \"telegraf.tessla\""),
        "{err}"
    );
}
