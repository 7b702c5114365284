//! Reading an effects file (TOML) into compiled user effects, with errors that name the
//! file, line and column (inside the expression when the error is in one) and what was
//! expected.

use super::expr::{self, Node, Program, CONSTANTS, FUNCTIONS, MAX_SLOTS, VARIABLES};
use super::{axis_of, inputs_of, intern, term, UserEffect, UserEffectDef, UserParam, UserSide};
use crate::units::SensorKind;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use toml::Spanned;

/// Errors of an effects file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum UserEffectError {
    /// The file could not be read (the operating system's reason follows as the cause).
    #[error("reading the effects file {path}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is not a valid effects file.
    #[error("{path}:{line}:{column}: {msg}")]
    Invalid {
        /// File (or `<effects>` for text given directly).
        path: String,
        /// Line, 1-based.
        line: usize,
        /// Column, 1-based (characters).
        column: usize,
        /// What is wrong and what was expected.
        msg: String,
    },
    /// An effect's expression is not finite on the data it is fitted or simulated on.
    #[error("effect '{id}': its expression is not finite at t = {t_s} s of run '{run}' ({state}); guard it (e.g. sqrt(abs(x)), max(x, 1e-9)) or fit other data")]
    NonFinite {
        /// Effect id.
        id: String,
        /// Run name.
        run: String,
        /// Time of the sample, s.
        t_s: f64,
        /// The state there, in words.
        state: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    effect: Vec<Spanned<RawEffect>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawValue {
    Int(i64),
    Num(f64),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEffect {
    id: Spanned<String>,
    sensor: Spanned<String>,
    output: Spanned<String>,
    expr: Spanned<String>,
    #[serde(default)]
    coefficients: Vec<Spanned<String>>,
    #[serde(default)]
    parameters: BTreeMap<String, Spanned<RawValue>>,
    #[serde(default)]
    description: String,
    #[serde(default)]
    side: Option<Spanned<String>>,
}

/// Line and column (1-based, characters) of a byte offset.
fn line_col(text: &str, byte: usize) -> (usize, usize) {
    let byte = byte.min(text.len());
    let before = text.get(..byte).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

struct Ctx<'a> {
    path: &'a str,
    text: &'a str,
}

impl Ctx<'_> {
    fn at(&self, byte: usize, msg: impl Into<String>) -> UserEffectError {
        let (line, column) = line_col(self.text, byte);
        UserEffectError::Invalid { path: self.path.to_string(), line, column, msg: msg.into() }
    }

    /// The byte offset in the file of character `pos` of a string value spanning `span`.
    fn inside(&self, span: std::ops::Range<usize>, value: &str, pos: usize) -> usize {
        let lit = self.text.get(span.start..).unwrap_or("");
        let open = if lit.starts_with("\"\"\"") || lit.starts_with("'''") { 3 } else { 1 };
        span.start + open + value.char_indices().nth(pos).map_or(value.len(), |(b, _)| b)
    }
}

/// Reads and compiles an effects file.
pub fn load_file(path: &Path) -> Result<Vec<Arc<UserEffect>>, UserEffectError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| UserEffectError::Io { path: path.display().to_string(), source })?;
    load_str(&path.display().to_string(), &text)
}

/// Compiles effect definitions given as TOML text; `label` names it in errors.
pub fn load_str(label: &str, text: &str) -> Result<Vec<Arc<UserEffect>>, UserEffectError> {
    let cx = Ctx { path: label, text };
    let raw: RawFile = toml::from_str(text).map_err(|e| {
        let at = e.span().map_or(0, |s| s.start);
        cx.at(at, format!("not a valid effects file: {}", e.message()))
    })?;
    if raw.effect.is_empty() {
        return Err(cx.at(0, "no effect: expected one or more [[effect]] tables with id, sensor, output and expr"));
    }
    let mut out: Vec<Arc<UserEffect>> = Vec::new();
    for e in raw.effect {
        let span = e.span();
        let e = e.into_inner();
        if out.iter().any(|o| o.def.id == *e.id.get_ref()) {
            return Err(cx.at(e.id.span().start, format!("effect '{}' is defined twice", e.id.get_ref())));
        }
        out.push(Arc::new(compile_raw(&cx, e, span.start)?));
    }
    Ok(out)
}

fn compile_raw(cx: &Ctx<'_>, e: RawEffect, at: usize) -> Result<UserEffect, UserEffectError> {
    let id = e.id.get_ref();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') {
        return Err(cx.at(e.id.span().start, format!("id '{id}': expected letters, digits, '-' or '_'")));
    }
    if crate::model::builtin_ids().contains(&id.as_str()) {
        return Err(cx.at(e.id.span().start, format!("id '{id}' is a catalogue effect: choose another id")));
    }
    let sensor = match e.sensor.get_ref().as_str() {
        "gyro" => SensorKind::Gyro,
        "accel" => SensorKind::Accel,
        other => return Err(cx.at(e.sensor.span().start, format!("sensor '{other}': expected \"gyro\" or \"accel\""))),
    };
    if axis_of(e.output.get_ref()).is_none() {
        let msg = format!("output '{}': expected \"x\", \"y\" or \"z\"", e.output.get_ref());
        return Err(cx.at(e.output.span().start, msg));
    }
    let side = match e.side.as_ref().map(|s| s.get_ref().as_str()) {
        None | Some("output") => UserSide::Output,
        Some("input") => UserSide::Input,
        Some(other) => {
            let at = e.side.as_ref().map_or(at, |s| s.span().start);
            return Err(cx.at(at, format!("side '{other}': expected \"output\" or \"input\"")));
        }
    };
    let mut parameters = Vec::new();
    for (name, v) in &e.parameters {
        let start = match v.get_ref() {
            RawValue::Int(i) => *i as f64,
            RawValue::Num(x) => *x,
            RawValue::Text(s) => constant(s).map_err(|m| cx.at(v.span().start, format!("parameter '{name}': {m}")))?,
        };
        if !start.is_finite() {
            return Err(cx.at(v.span().start, format!("parameter '{name}': expected a finite start value")));
        }
        parameters.push(UserParam { name: name.clone(), start });
    }
    let def = UserEffectDef {
        id: id.clone(),
        sensor,
        output: e.output.get_ref().clone(),
        expr: e.expr.get_ref().clone(),
        coefficients: e.coefficients.iter().map(|c| c.get_ref().clone()).collect(),
        parameters,
        description: e.description.clone(),
        side,
    };
    compile(&def).map_err(|(pos, msg)| match pos {
        Some(p) => cx.at(cx.inside(e.expr.span(), e.expr.get_ref(), p), msg),
        None => cx.at(at, format!("effect '{id}': {msg}")),
    })
}

/// The value of a constant expression such as `4 deg` or `0.07`.
fn constant(text: &str) -> Result<f64, String> {
    let n = expr::parse(text, &[]).map_err(|e| format!("'{text}' at column {}: {}", e.pos + 1, e.msg))?;
    Program::compile(&n).map(|p| p.eval(&[])).map_err(|e| e.msg)
}

/// Whether `s` may name a coefficient or parameter.
fn valid_name(s: &str) -> Result<(), String> {
    let ok = s.chars().next().is_some_and(|c| c.is_alphabetic() || c == '_')
        && s.chars().all(|c| c.is_alphanumeric() || c == '_');
    if !ok {
        return Err(format!(
            "'{s}' cannot name a coefficient or parameter: expected a letter then letters, digits or '_'"
        ));
    }
    if VARIABLES.contains(&s) || FUNCTIONS.iter().any(|(f, _)| *f == s) || CONSTANTS.iter().any(|(c, _)| *c == s) {
        return Err(format!("'{s}' is a variable, function or constant of the language: choose another name"));
    }
    Ok(())
}

/// Compiles a definition (from a file or a profile). Errors carry the character offset in
/// the expression when they are in it.
pub(crate) fn compile(def: &UserEffectDef) -> Result<UserEffect, (Option<usize>, String)> {
    let axis = axis_of(&def.output).ok_or((None, format!("output '{}': expected x, y or z", def.output)))?;
    let own: Vec<&str> =
        def.coefficients.iter().map(String::as_str).chain(def.parameters.iter().map(|p| p.name.as_str())).collect();
    for (i, n) in own.iter().enumerate() {
        valid_name(n).map_err(|m| (None, m))?;
        if own[..i].contains(n) {
            return Err((None, format!("'{n}' is named twice among the coefficients and parameters")));
        }
    }
    if VARIABLES.len() + own.len() > MAX_SLOTS {
        return Err((None, format!("at most {} coefficients and parameters", MAX_SLOTS - VARIABLES.len())));
    }
    let names: Vec<&str> = VARIABLES.iter().copied().chain(own.iter().copied()).collect();
    let node = expr::parse(&def.expr, &names).map_err(|e| (Some(e.pos), e.msg))?;
    for (i, n) in own.iter().enumerate() {
        if !node.uses(VARIABLES.len() + i) {
            let what = if i < def.coefficients.len() { "coefficient" } else { "parameter" };
            return Err((None, format!("{what} '{n}' is never used in the expression '{}'", def.expr)));
        }
    }
    let nc = def.coefficients.len();
    let coef_slots = VARIABLES.len()..VARIABLES.len() + nc;
    let mut regs = Vec::new();
    if def.side == UserSide::Output {
        if nc == 0 {
            return Err((None, "an output-side effect needs at least one coefficient (e.g. expr = \"k * …\", coefficients = [\"k\"]): its size is fitted by least squares".into()));
        }
        let mut rest: Node = node.clone();
        for (j, c) in def.coefficients.iter().enumerate() {
            let d = node.derivative(VARIABLES.len() + j).filter(|d| !d.uses_any(coef_slots.clone())).ok_or_else(|| {
                (None, format!("coefficient '{c}' does not enter linearly (it is multiplied by a coefficient, divided by, or inside a function): list it under parameters"))
            })?;
            regs.push(Program::compile(&d).map_err(|e| (None, e.msg))?);
            rest = rest.substitute(VARIABLES.len() + j, 0.0);
        }
        if rest != Node::Num(0.0) {
            return Err((None, "every term of the expression must carry a coefficient (with all coefficients 0 it is not 0): an offset without a coefficient cannot be fitted".into()));
        }
    } else {
        let own_vars = match def.sensor {
            SensorKind::Gyro => 0..3,
            SensorKind::Accel => 6..9,
        };
        if let Some(v) = (0..VARIABLES.len()).find(|v| !own_vars.contains(v) && node.uses(*v)) {
            return Err((
                None,
                format!(
                    "an input-side effect reads only its sensor's own input ({}); it reads '{}'",
                    VARIABLES[own_vars].join(", "),
                    VARIABLES[v]
                ),
            ));
        }
    }
    let value = Program::compile(&node).map_err(|e| (None, e.msg))?;
    let id = intern(&def.id);
    let terms = regs.iter().enumerate().map(|(j, _)| term(def, id, axis, j, &def.coefficients[j])).collect();
    let explain = if def.description.is_empty() {
        format!("User effect: {} on {} {} ({} side).", def.expr, def.sensor.as_str(), def.output, side_word(def.side))
    } else {
        format!(
            "{} (user effect: {} on {} {}, {} side)",
            def.description,
            def.expr,
            def.sensor.as_str(),
            def.output,
            side_word(def.side)
        )
    };
    Ok(UserEffect {
        def: def.clone(),
        id,
        explain: intern(&explain),
        axis,
        value,
        regs,
        terms,
        bound: def.parameters.iter().map(|p| p.start).collect(),
        reg_extra: super::regressor_slots(def, &def.parameters.iter().map(|p| p.start).collect::<Vec<_>>()),
        inputs: inputs_of(&node),
    })
}

fn side_word(s: UserSide) -> &'static str {
    match s {
        UserSide::Output => "output",
        UserSide::Input => "input",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KNEE: &str = r#"
[[effect]]
id = "gyro-x-knee"
sensor = "gyro"
output = "x"
expr = "k * max(w_x - w0, 0)"
coefficients = ["k"]
parameters = { w0 = "4 deg" }
description = "scale step above a rate"
"#;

    #[test]
    fn reads_the_issue_form_and_evaluates() {
        let v = load_str("f.toml", KNEE).unwrap();
        let e = &v[0];
        assert!((e.def.parameters[0].start - 4.0f64.to_radians()).abs() < 1e-15);
        let s = crate::model::State { w: [0.1, 0.0, 0.0], ..Default::default() };
        use crate::model::Effect;
        assert!((e.regressor(0, &s) - (0.1 - 4.0f64.to_radians())).abs() < 1e-15);
        let inline = KNEE.replace("\"4 deg\"", "0.0698");
        assert!((load_str("f.toml", &inline).unwrap()[0].def.parameters[0].start - 0.0698).abs() < 1e-15);
    }

    fn err(text: &str) -> String {
        load_str("f.toml", text).unwrap_err().to_string()
    }

    #[test]
    fn errors_name_file_line_column_and_expectation() {
        let bad = KNEE.replace("max(w_x - w0, 0)", "max(w_q - w0, 0)");
        // Line 6, the expression starts at column 9: `w_q` is its 9th character (1-based).
        assert!(err(&bad).starts_with("f.toml:6:17: unknown name 'w_q'"), "{}", err(&bad));
        let bad = KNEE.replace("max(w_x - w0, 0)", "max(w_x - w0, 0");
        assert!(err(&bad).contains("f.toml:6:28: expected ',' or ')'"), "{}", err(&bad));
        let bad = KNEE.replace("coefficients = [\"k\"]", "coefficients = [\"k\", \"m\"]");
        assert!(err(&bad).contains("coefficient 'm' is never used"), "{}", err(&bad));
        let bad = KNEE.replace("k * max", "k * k * max");
        assert!(err(&bad).contains("does not enter linearly"), "{}", err(&bad));
        let bad = KNEE.replace("sensor = \"gyro\"", "sensor = \"gyr\"");
        assert!(err(&bad).starts_with("f.toml:4:10: sensor 'gyr'"), "{}", err(&bad));
        assert!(err("[[effect]\n").starts_with("f.toml:1:"), "{}", err("[[effect]\n"));
        let bad = KNEE.replace("expr = \"k * max(w_x - w0, 0)\"", "expr = \"k * max(w_x - w0, 0) + w_y\"");
        assert!(err(&bad).contains("must carry a coefficient"), "{}", err(&bad));
    }
}
