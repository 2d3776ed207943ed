//! Parser behaviour: precedence, significant newlines, literals, statements, error recovery.

use tessla_syntax::ast::*;
use tessla_syntax::diag::Category;
use tessla_syntax::source::SourceMap;

fn parse(text: &str) -> (File, Vec<tessla_syntax::diag::Diagnostic>, SourceMap) {
    let mut map = SourceMap::new();
    let id = map.add("t.tessla", None, text.to_string());
    let (f, d) = tessla_syntax::parse(&map.get(id).text, id);
    (f, d, map)
}

fn ok(text: &str) -> File {
    let (f, d, map) = parse(text);
    assert!(
        d.is_empty(),
        "unexpected diagnostics: {:?}",
        d.iter().map(|d| d.one_line(&map)).collect::<Vec<_>>()
    );
    f
}

fn def_body(f: &File, i: usize) -> &Expr {
    match &f.statements[i] {
        Statement::Def(Def {
            body: Body::Expr { expr, .. },
            ..
        }) => expr,
        s => panic!("not a def: {s:?}"),
    }
}

/// A compact prefix form of an expression, for precedence assertions.
fn show(e: &Expr) -> String {
    match &e.kind {
        ExprKind::Var(i) => i.name.clone(),
        ExprKind::Int { value, unit } => {
            format!("{value}{}", unit.as_ref().map_or("", |u| u.name.as_str()))
        }
        ExprKind::Float(f) => format!("{f:?}"),
        ExprKind::Binary { op, lhs, rhs } => {
            format!("({} {} {})", op.symbol(), show(lhs), show(rhs))
        }
        ExprKind::Unary { op, operand } => format!("({op:?} {})", show(operand)),
        ExprKind::Call { function, args, .. } => format!(
            "{}({})",
            show(function),
            args.iter()
                .flatten()
                .map(|a| show(&a.value))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        ExprKind::Member { object, field } => format!("{}.{}", show(object), field.name),
        ExprKind::If {
            cond,
            then_branch,
            else_branch,
            ..
        } => {
            format!(
                "(if {} {} {})",
                show(cond),
                show(then_branch),
                show(else_branch)
            )
        }
        ExprKind::Tuple(es) => format!("({})", es.iter().map(show).collect::<Vec<_>>().join(", ")),
        ExprKind::Lambda { params, body } => format!(
            "(fn {} {})",
            params
                .iter()
                .map(|p| p.name.name.clone())
                .collect::<Vec<_>>()
                .join(" "),
            show(body)
        ),
        ExprKind::Block { defs, result } => format!("{{{} defs; {}}}", defs.len(), show(result)),
        ExprKind::Record(ms) => format!(
            "{{{}}}",
            ms.iter()
                .map(|(n, v)| format!("{}={}", n.name, show(v)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        ExprKind::Str { parts, .. } => format!("str{}", parts.len()),
        ExprKind::RootMember(i) => format!("__root__.{}", i.name),
    }
}

#[test]
fn precedence_follows_tessla() {
    let f = ok(
        "def a = 1 + 2 * 3 - 4\ndef b = x < y && y <= z || !w\ndef c = a +. b *. c <. d\ndef e = -x * 2\ndef g = 1 << 2 & 3 | 4",
    );
    assert_eq!(show(def_body(&f, 0)), "(- (+ 1 (* 2 3)) 4)");
    assert_eq!(show(def_body(&f, 1)), "(|| (&& (< x y) (<= y z)) (Not w))");
    assert_eq!(show(def_body(&f, 2)), "(<. (+. a (*. b c)) d)");
    assert_eq!(show(def_body(&f, 3)), "(* (Neg x) 2)");
    assert_eq!(show(def_body(&f, 4)), "(| (& (<< 1 2) 3) 4)");
}

#[test]
fn newlines_continue_after_operators_and_in_brackets_only() {
    let f = ok("def a = x +\n  y\ndef b = f(\n  x,\n  y\n)\ndef c = if x\n then 1\n else 2");
    assert_eq!(show(def_body(&f, 0)), "(+ x y)");
    assert_eq!(show(def_body(&f, 1)), "f(x, y)");
    assert_eq!(show(def_body(&f, 2)), "(if x 1 2)");
    // A newline before an operator ends the statement: `+ y` is then not a statement.
    let (_, d, _) = parse("def a = x\n+ y\n");
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].category, Category::Syntax);
}

#[test]
fn literals_time_units_and_comments() {
    let f = ok(
        "def a = 100ms # comment\ndef b = 5 s -- another\ndef c = 1.5e3\ndef d = 0x1F\ndef e = \"a${x}b\"\ndef g = f\"${x}%.2f\"",
    );
    assert_eq!(show(def_body(&f, 0)), "100ms");
    assert_eq!(show(def_body(&f, 1)), "5s");
    assert_eq!(show(def_body(&f, 2)), "1500.0");
    assert_eq!(show(def_body(&f, 3)), "31");
    assert_eq!(show(def_body(&f, 4)), "str3");
    match &def_body(&f, 5).kind {
        ExprKind::Str {
            parts,
            format: true,
        } => {
            assert!(matches!(&parts[0], StrPart::Interp { format: Some(s), .. } if s == "%.2f"))
        }
        k => panic!("{k:?}"),
    }
}

#[test]
fn statements_annotations_and_output_names() {
    let f = ok(
        "include \"lib.tessla\"\ndef @TelegrafIn(measurement: String, tags: String, field: String)\n@TelegrafIn(\"m\", \"\", \"speed\")\nin speed: Events[Float]\nout speed +. 1.0\nout speed as s\nout *\nliftable def sq(x: Float): Float = x *. x\ndef ext(a: Int): Int = extern(\"add\")",
    );
    assert_eq!(f.includes[0].path, "lib.tessla");
    assert!(
        matches!(&f.statements[0], Statement::AnnotationDef { name, params, global: false, .. } if name.name == "TelegrafIn" && params.len() == 3)
    );
    match &f.statements[1] {
        Statement::In {
            annotations,
            name,
            ty: Type::App { name: tn, args, .. },
            ..
        } => {
            assert_eq!(annotations[0].name.name, "TelegrafIn");
            assert_eq!(annotations[0].args.len(), 3);
            assert_eq!(name.name, "speed");
            assert_eq!(tn.name, "Events");
            assert!(matches!(&args[0], Type::Name(i) if i.name == "Float"));
        }
        s => panic!("{s:?}"),
    }
    assert!(
        matches!(&f.statements[2], Statement::Out(o) if o.source_text == "speed +. 1.0" && o.alias.is_none())
    );
    assert!(matches!(&f.statements[3], Statement::Out(o) if o.alias.as_ref().unwrap().name == "s"));
    assert!(matches!(&f.statements[4], Statement::OutAll { .. }));
    assert!(
        matches!(&f.statements[5], Statement::Def(d) if d.liftable && d.params.as_ref().unwrap().len() == 1)
    );
    assert!(
        matches!(&f.statements[6], Statement::Def(Def { body: Body::Extern { name, .. }, .. }) if name == "add")
    );
}

#[test]
fn blocks_records_lambdas_tuples_and_where() {
    let f = ok(
        "def a = { def x = 1; x + 1 }\ndef b = {x = 1, y: 2}\ndef c = (x: Int, y) => x + y\ndef d = (1, 2)\ndef e = x where { def x = 3 }\ndef g = List.append(l, 1)\ndef h = f[Int](x)",
    );
    assert_eq!(show(def_body(&f, 0)), "{1 defs; (+ x 1)}");
    assert_eq!(show(def_body(&f, 1)), "{x=1, y=2}");
    assert_eq!(show(def_body(&f, 2)), "(fn x y (+ x y))");
    assert_eq!(show(def_body(&f, 3)), "(1, 2)");
    assert!(
        matches!(&f.statements[4], Statement::Def(Def { body: Body::Expr { where_defs, .. }, .. }) if where_defs.len() == 1)
    );
    assert_eq!(show(def_body(&f, 5)), "List.append(l, 1)");
    assert!(
        matches!(&def_body(&f, 6).kind, ExprKind::Call { type_args, .. } if type_args.len() == 1)
    );
}

#[test]
fn errors_name_the_place_and_parsing_recovers() {
    let (f, d, map) = parse("in x: Events[Int]\ndef a = x +\ndef b = (x\ndef c = x * 2\nout c\n");
    assert!(d.len() >= 2, "{d:?}");
    assert!(d.iter().all(|d| d.category == Category::Syntax));
    let first = d[0].one_line(&map);
    assert!(first.starts_with("t.tessla:3:1"), "{first}");
    // The good statements around the broken ones are kept.
    let names: Vec<_> = f
        .statements
        .iter()
        .filter_map(|s| match s {
            Statement::Def(d) => Some(d.name.name.as_str()),
            _ => None,
        })
        .collect();
    assert!(names.contains(&"c"), "{names:?}");
    assert!(matches!(f.statements.last(), Some(Statement::Out(_))));
}

#[test]
fn keywords_and_bad_characters_are_reported() {
    let (_, d, map) = parse("def in = 3\ndef x = 4 ? 5\n");
    let msgs: Vec<_> = d.iter().map(|d| d.one_line(&map)).collect();
    assert!(msgs.iter().any(|m| m.contains("keyword")), "{msgs:?}");
    assert!(
        msgs.iter()
            .any(|m| m.contains("t.tessla:2:11") && m.contains("unexpected character")),
        "{msgs:?}"
    );
}

#[test]
fn string_escapes_follow_tessla() {
    let f = ok(r#"def s = "a\n\t\r\a\\\"\$\%b""#);
    match &def_body(&f, 0).kind {
        ExprKind::Str { parts, .. } => {
            assert_eq!(parts, &[StrPart::Text("a\n\t\r\u{7}\\\"$%b".into())]);
        }
        k => panic!("not a string: {k:?}"),
    }
    let (_, d, map) = parse("def s = \"x\\dy\"\nout s");
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].message, "Invalid escape sequence '\\d' in string");
    assert!(d[0].help.is_some());
    assert!(
        d[0].one_line(&map).starts_with("t.tessla:1:11"),
        "{}",
        d[0].one_line(&map)
    );
}

#[test]
fn single_expressions_parse_on_their_own() {
    let mut map = SourceMap::new();
    let id = map.add("v", None, "Some((1, ${x = 2}))".to_string());
    let (e, d) = tessla_syntax::parse_expr(&map.get(id).text, id);
    assert!(d.is_empty(), "{d:?}");
    assert_eq!(show(&e.unwrap()), "Some((1, {x=2}))");
    for bad in ["1 2", "", "(1", "def x = 1"] {
        let (e, d) = tessla_syntax::parse_expr(bad, id);
        assert!(e.is_none() && !d.is_empty(), "{bad:?} parsed");
        assert!(d.iter().all(|d| d.category == Category::Syntax));
    }
}

#[test]
fn errors_carry_fixes_where_one_is_known() {
    let (_, d, map) = parse("in x: Events[Int]\nout (x + 1\n");
    let first = &d[0];
    assert_eq!(first.help.as_deref(), Some("add the closing `)`"));
    let (at, note) = &first.notes_at[0];
    assert_eq!(note, "unclosed `(` opened here");
    assert!(
        map.location(*at).starts_with("t.tessla:2:5"),
        "{}",
        map.location(*at)
    );

    let (_, d, _) = parse("in x: Events[Int]\ndef y = x = 1\nout y");
    assert_eq!(d[0].help.as_deref(), Some("use `==` to compare values"));

    let (_, d, map) = parse("in x\nout x");
    assert_eq!(
        d[0].help.as_deref(),
        Some("an input needs its type: `in x: Events[Int]`")
    );
    // The caret sits at the end of the line, not across the line break.
    let span = d[0].span.unwrap();
    assert_eq!(span.start, span.end);
    assert!(d[0].one_line(&map).starts_with("t.tessla:1:5"));
}
