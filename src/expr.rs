//! Parameter values and the small arithmetic language graph files use to derive them.
//!
//! A node param in a graph file may be a literal (`0.5`, `"gaussian"`, `[64, 64, 32]`),
//! a reference to a graph param (`"$box"`, which keeps the referenced value's type), or an
//! expression (`"= sqrt(2*temperature*dt)"`), evaluated in f64 over the graph params.
//!
//! Written here rather than taken from a crate: the well-known evaluators either divide
//! integers as integers (`2/3 = 0`, a silent trap in physics formulas) or are AGPL.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

use thiserror::Error;

/// A bad `NAME=VALUE` param assignment (a command line's `--set`).
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum OverrideError {
    #[error("`{0}`: expected NAME=VALUE")]
    Malformed(String),
    #[error("{name}: {source}")]
    Value {
        name: String,
        #[source]
        source: ExprError,
    },
    #[error("{0} is given twice")]
    Repeated(String),
}

/// Graph param values from `NAME=VALUE` assignments (values as [`ParamValue::from_cli`]
/// reads them), each name at most once: what `LoadOptions::overrides` takes.
pub fn parse_overrides(
    assignments: &[String],
) -> Result<BTreeMap<String, ParamValue>, OverrideError> {
    let mut out = BTreeMap::new();
    for a in assignments {
        let (name, value) = a
            .split_once('=')
            .filter(|(n, v)| !n.trim().is_empty() && !v.is_empty())
            .ok_or_else(|| OverrideError::Malformed(a.clone()))?;
        let name = name.trim();
        let v = ParamValue::from_cli(value).map_err(|source| OverrideError::Value {
            name: name.to_string(),
            source,
        })?;
        if out.insert(name.to_string(), v).is_some() {
            return Err(OverrideError::Repeated(name.to_string()));
        }
    }
    Ok(out)
}

/// The value of a param after resolution.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    Number(f64),
    Text(String),
    Numbers(Vec<f64>),
    Bool(bool),
}

impl ParamValue {
    /// Converts a JSON literal. Objects, nested arrays and nulls are not param values.
    pub fn from_json(v: &serde_json::Value) -> Result<ParamValue, ExprError> {
        use serde_json::Value;
        match v {
            Value::Number(n) => n
                .as_f64()
                .map(ParamValue::Number)
                .ok_or_else(|| ExprError::Literal(format!("number {n} is out of range"))),
            Value::String(s) => Ok(ParamValue::Text(s.clone())),
            Value::Bool(b) => Ok(ParamValue::Bool(*b)),
            Value::Array(items) => items
                .iter()
                .map(|x| {
                    x.as_f64().ok_or_else(|| {
                        ExprError::Literal(format!("array element {x} is not a number"))
                    })
                })
                .collect::<Result<Vec<_>, _>>()
                .map(ParamValue::Numbers),
            Value::Null => Err(ExprError::Literal("null is not a param value".into())),
            Value::Object(_) => Err(ExprError::Literal("an object is not a param value".into())),
        }
    }

    /// Parses a command-line `--set` value: a JSON number or array, `true`/`false`, or else
    /// a plain string.
    pub fn from_cli(text: &str) -> Result<ParamValue, ExprError> {
        let t = text.trim();
        if t.starts_with('[') {
            let v: serde_json::Value = serde_json::from_str(t)
                .map_err(|e| ExprError::Literal(format!("`{t}` is not a JSON array: {e}")))?;
            return ParamValue::from_json(&v);
        }
        if let Ok(v @ serde_json::Value::Number(_)) = serde_json::from_str::<serde_json::Value>(t) {
            return ParamValue::from_json(&v);
        }
        match t {
            "true" => Ok(ParamValue::Bool(true)),
            "false" => Ok(ParamValue::Bool(false)),
            _ => Ok(ParamValue::Text(t.to_string())),
        }
    }

    pub fn type_name(&self) -> &'static str {
        match self {
            ParamValue::Number(_) => "a number",
            ParamValue::Text(_) => "a string",
            ParamValue::Numbers(_) => "an array of numbers",
            ParamValue::Bool(_) => "a boolean",
        }
    }

    pub fn to_json(&self) -> serde_json::Value {
        match self {
            ParamValue::Number(x) => json_number(*x),
            ParamValue::Text(s) => serde_json::Value::String(s.clone()),
            ParamValue::Numbers(v) => {
                serde_json::Value::Array(v.iter().map(|&x| json_number(x)).collect())
            }
            ParamValue::Bool(b) => serde_json::Value::Bool(*b),
        }
    }
}

fn json_number(x: f64) -> serde_json::Value {
    serde_json::Number::from_f64(x)
        .map(serde_json::Value::Number)
        .unwrap_or(serde_json::Value::Null)
}

/// A number as people read it: in exponent form from 1e15 up and below 1e-6 (`5e-324`,
/// not 324 digits).
pub fn fmt_number(x: f64) -> String {
    if x.abs() >= 1e15 || (x != 0.0 && x.abs() < 1e-6) {
        format!("{x:e}")
    } else {
        x.to_string()
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Number(x) => write!(f, "{}", fmt_number(*x)),
            ParamValue::Text(s) => write!(f, "\"{s}\""),
            ParamValue::Numbers(v) => {
                write!(f, "[")?;
                for (i, x) in v.iter().enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{}", fmt_number(*x))?;
                }
                write!(f, "]")
            }
            ParamValue::Bool(b) => write!(f, "{b}"),
        }
    }
}

/// Why a param value or an expression could not be evaluated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ExprError {
    /// A literal that is not a param value (an object, a null, a nested array).
    #[error("{0}")]
    Literal(String),
    /// The text does not parse.
    #[error("{problem} in expression `{expr}`")]
    Syntax { problem: String, expr: String },
    /// A value used where its kind does not fit (a string in arithmetic, a wrong
    /// argument count).
    #[error("{problem} in expression `{expr}`")]
    Type { problem: String, expr: String },
    /// The expression as a whole gives no usable value.
    #[error("expression `{expr}` {problem}")]
    Result { problem: String, expr: String },
    /// A name that is no graph param (nor `pi`).
    #[error("unknown param `{name}` (graph params: {known}){}", match expr { Some(e) => format!(" in expression `{e}`"), None => String::new() })]
    UnknownName {
        name: String,
        known: String,
        /// The expression it appears in (none for a `$name` reference).
        expr: Option<String>,
    },
    /// A graph param that has a problem of its own (a bad value, a default that does not
    /// evaluate): what reads it is not evaluated, and its problem is the one to report.
    #[error("param `{name}` has no value (it has a problem of its own)")]
    Unresolved { name: String },
    #[error("unknown function `{name}` in expression `{expr}`")]
    UnknownFunction { name: String, expr: String },
    /// A host function refused its arguments.
    #[error("{name}: {message} (in expression `{expr}`)")]
    Function {
        name: String,
        message: String,
        expr: String,
    },
}

impl ExprError {
    /// Whether the problem is with the values the expression was given rather than with
    /// its text: a host function refusing its arguments (a planner outside its domain).
    /// A node's params with such a problem are as wrong as an out-of-range value, and
    /// only matter where the node runs.
    pub fn depends_on_values(&self) -> bool {
        matches!(self, ExprError::Function { .. })
    }
}

/// Where a param value comes from: the top-level graph's params it is computed from
/// (what a user sets with `--set`), transitively through subgraphs, and the last
/// expression on the way. A problem found in a derived value (a node param out of range,
/// a planner refusing its arguments) names these, not only the derived value.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Origin {
    /// By name, each once.
    pub sources: Vec<OriginParam>,
    /// The expression that computed the value from them (`fcm_support(...)`), if any.
    pub via: Option<String>,
}

/// A top-level graph param a value is computed from, with its value.
#[derive(Clone, Debug, PartialEq)]
pub struct OriginParam {
    pub name: String,
    pub value: ParamValue,
    /// Set by the user (`--set`), not its default.
    pub given: bool,
}

/// Expressions longer than this are shown cut (an origin's `via`).
const MAX_SHOWN_EXPR: usize = 80;

impl Origin {
    /// A top-level param itself.
    pub fn param(name: &str, value: &ParamValue, given: bool) -> Self {
        Origin {
            sources: vec![OriginParam {
                name: name.into(),
                value: value.clone(),
                given,
            }],
            via: None,
        }
    }

    /// The origin of a value computed from several: their sources together (and the one
    /// expression where there is one value).
    pub fn union<'o>(origins: impl IntoIterator<Item = &'o Origin>) -> Origin {
        let all: Vec<&Origin> = origins.into_iter().collect();
        if let [one] = all[..] {
            return one.clone();
        }
        let mut out = Origin::default();
        for o in all {
            out.merge(o);
        }
        out
    }

    fn merge(&mut self, other: &Origin) {
        for p in &other.sources {
            if !self.sources.iter().any(|q| q.name == p.name) {
                self.sources.push(p.clone());
            }
        }
        self.sources.sort_by(|a, b| a.name.cmp(&b.name));
    }

    /// "computed from `radius` = 5e-324 via `fcm_support(...)`": the sources the user set
    /// (all of them where the user set none), or `None` where there are none (a
    /// subgraph's own constant).
    pub fn describe(&self) -> Option<String> {
        let given: Vec<&OriginParam> = self.sources.iter().filter(|p| p.given).collect();
        let shown = if given.is_empty() {
            self.sources.iter().collect()
        } else {
            given
        };
        if shown.is_empty() {
            return None;
        }
        let names: Vec<String> = shown
            .iter()
            .map(|p| format!("`{}` = {}", p.name, p.value))
            .collect();
        Some(match &self.via {
            Some(e) => {
                let e = if e.chars().count() > MAX_SHOWN_EXPR {
                    format!("{}...", e.chars().take(MAX_SHOWN_EXPR).collect::<String>())
                } else {
                    e.clone()
                };
                format!("computed from {} via `{e}`", names.join(", "))
            }
            None => format!("from graph param {}", names.join(", ")),
        })
    }

    /// `message` followed by ` (computed from ...)` where there is something to say.
    pub fn explain(&self, message: impl Into<String>) -> String {
        let message = message.into();
        match self.describe() {
            Some(d) => format!("{message} ({d})"),
            None => message,
        }
    }
}

/// The graph params an expression reads (every name not called as a function and not
/// `pi`), in order of appearance; none for text that does not lex.
pub fn names_read(text: &str) -> Vec<String> {
    let Ok(toks) = lex(text) else {
        return Vec::new();
    };
    let mut names = Vec::new();
    for (i, t) in toks.iter().enumerate() {
        if let Tok::Name(name) = t
            && toks.get(i + 1) != Some(&Tok::Op('('))
            && name != "pi"
            && !names.contains(name)
        {
            names.push(name.clone());
        }
    }
    names
}

/// Names visible to expressions, with the host functions they may call.
#[derive(Clone)]
pub struct Scope<'f> {
    values: BTreeMap<String, ParamValue>,
    /// Where each value comes from ([`Origin`]); absent: a constant of its file.
    origins: BTreeMap<String, Origin>,
    /// Declared names without a value: a param whose own value has a problem. Reading
    /// one is [`ExprError::Unresolved`], so that one bad value is one problem, not one
    /// more for everything computed from it.
    unresolved: BTreeSet<String>,
    functions: &'f HostFunctions,
}

impl<'f> Scope<'f> {
    /// An empty scope whose expressions may call `functions`.
    pub fn new(functions: &'f HostFunctions) -> Self {
        Scope {
            values: BTreeMap::new(),
            origins: BTreeMap::new(),
            unresolved: BTreeSet::new(),
            functions,
        }
    }

    pub fn insert(&mut self, name: String, value: ParamValue) {
        self.unresolved.remove(&name);
        self.origins.remove(&name);
        self.values.insert(name, value);
    }

    /// [`Scope::insert`], with where the value comes from.
    pub fn insert_with_origin(&mut self, name: String, value: ParamValue, origin: Origin) {
        self.insert(name.clone(), value);
        self.origins.insert(name, origin);
    }

    /// Where a param as written in a graph file takes its value from: a `$name`
    /// reference, that name's origin; an `= expression`, the origins of every name it
    /// reads, via the expression; a literal, nowhere.
    pub fn origin_of(&self, v: &serde_json::Value) -> Origin {
        let serde_json::Value::String(s) = v else {
            return Origin::default();
        };
        if let Some(name) = s.strip_prefix('$') {
            return self.origins.get(name.trim()).cloned().unwrap_or_default();
        }
        let Some(expr) = s.strip_prefix('=') else {
            return Origin::default();
        };
        let mut origin = Origin {
            sources: Vec::new(),
            via: Some(expr.trim().to_string()),
        };
        for name in names_read(expr) {
            if let Some(o) = self.origins.get(&name) {
                origin.merge(o);
            }
        }
        origin
    }

    /// Declares `name` without a value: its own value has a problem (reported by the
    /// caller), and what reads it gives [`ExprError::Unresolved`].
    pub fn insert_unresolved(&mut self, name: String) {
        self.values.remove(&name);
        self.origins.remove(&name);
        self.unresolved.insert(name);
    }

    /// The error of reading `name` when it has no value: unresolved or unknown.
    fn missing(&self, name: &str, expr: Option<&str>) -> ExprError {
        if self.unresolved.contains(name) {
            ExprError::Unresolved { name: name.into() }
        } else {
            ExprError::UnknownName {
                name: name.into(),
                known: known_names(self),
                expr: expr.map(|e| e.trim().into()),
            }
        }
    }

    pub fn get(&self, name: &str) -> Option<&ParamValue> {
        self.values.get(name)
    }

    /// Every declared name, with a value or not, in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        let mut names: Vec<&str> = self
            .values
            .keys()
            .chain(&self.unresolved)
            .map(|s| s.as_str())
            .collect();
        names.sort_unstable();
        names.into_iter()
    }
}

/// Resolves a param as written in a graph file: a literal, a `$name` reference, or an
/// `= expression` (a number or an array of numbers).
pub fn resolve(v: &serde_json::Value, scope: &Scope) -> Result<ParamValue, ExprError> {
    if let serde_json::Value::String(s) = v {
        if let Some(name) = s.strip_prefix('$') {
            let name = name.trim();
            return scope
                .get(name)
                .cloned()
                .ok_or_else(|| scope.missing(name, None));
        }
        if let Some(expr) = s.strip_prefix('=') {
            return evaluate(expr, scope);
        }
    }
    ParamValue::from_json(v)
}

fn known_names(scope: &Scope) -> String {
    scope.names().collect::<Vec<_>>().join(", ")
}

/// A function graph expressions may call besides the arithmetic ones: the host-side f64
/// planners of node families (an FFT-friendly size, an FCM grid from a radius).
#[derive(Clone, Copy)]
pub struct HostFunction {
    pub name: &'static str,
    /// Shown in docs: the arguments and what comes back.
    pub doc: &'static str,
    /// Its error says what is wrong with the arguments.
    pub call: fn(&[ParamValue]) -> Result<ParamValue, String>,
}

/// The host functions expressions may call, by name. The node families fill it
/// (`nodes::registry`); loading finds it in the registry it is given.
#[derive(Clone, Default)]
pub struct HostFunctions {
    /// In the order added (the order `mesoflow nodes` lists them).
    by_name: indexmap::IndexMap<&'static str, HostFunction>,
}

impl HostFunctions {
    /// Adds a function. Two functions with one name are a programming error.
    pub fn add(&mut self, f: HostFunction) {
        let previous = self.by_name.insert(f.name, f);
        assert!(previous.is_none(), "host function `{}` added twice", f.name);
    }

    pub fn get(&self, name: &str) -> Option<&HostFunction> {
        self.by_name.get(name)
    }

    /// Every function, in the order added.
    pub fn iter(&self) -> impl Iterator<Item = &HostFunction> {
        self.by_name.values()
    }
}

/// Evaluates an expression to a number.
///
/// Grammar: numbers, names of graph params, `+ - * / ^` (power, right-associative),
/// unary minus, parentheses, indexing of array params (`box[0]`), array literals
/// (`[a, b, c]`), strings in single quotes, the constant `pi`, the functions sqrt, cbrt,
/// exp, log (natural), log10, sin, cos, tan, atan, abs, floor, ceil, round, pow(x, y),
/// min(...), max(...), sum(...), prod(...) (the last four also take arrays), eq(a, b)
/// (true when two numbers, arrays or strings are equal: `"enabled": "= eq(range,
/// 'short')"` picks a graph's path by a choice param), and the host functions of the
/// scope.
pub fn eval(text: &str, scope: &Scope) -> Result<f64, ExprError> {
    match evaluate(text, scope)? {
        ParamValue::Number(x) => Ok(x),
        other => Err(ExprError::Result {
            problem: format!("gives {} where a number is needed", other.type_name()),
            expr: text.trim().into(),
        }),
    }
}

/// Evaluates an expression to a number or an array of numbers.
pub fn evaluate(text: &str, scope: &Scope) -> Result<ParamValue, ExprError> {
    let toks = lex(text)?;
    // An unknown name is a problem of the expression itself, to be reported even where
    // it also reads an unresolved param (whose problem is reported on its own).
    for (i, t) in toks.iter().enumerate() {
        if let Tok::Name(name) = t
            && toks.get(i + 1) != Some(&Tok::Op('('))
            && name != "pi"
            && scope.get(name).is_none()
            && !scope.unresolved.contains(name)
        {
            return Err(scope.missing(name, Some(text)));
        }
    }
    let mut p = Parser {
        src: text,
        toks,
        pos: 0,
        scope,
        depth: 0,
    };
    let v = p.expr()?;
    if p.pos != p.toks.len() {
        return Err(ExprError::Syntax {
            problem: format!("unexpected `{}`", p.toks[p.pos].text()),
            expr: text.trim().into(),
        });
    }
    let finite = |x: f64| {
        if x.is_finite() {
            Ok(x)
        } else {
            Err(ExprError::Result {
                problem: format!("is not finite ({x})"),
                expr: text.trim().into(),
            })
        }
    };
    match v {
        V::Num(x) => finite(x).map(ParamValue::Number),
        V::Arr(a) => a
            .into_iter()
            .map(finite)
            .collect::<Result<Vec<_>, _>>()
            .map(ParamValue::Numbers),
        V::Bool(b) => Ok(ParamValue::Bool(b)),
        V::Text(_) => Err(ExprError::Result {
            problem: "gives a string; write the string itself instead".into(),
            expr: text.trim().into(),
        }),
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Str(String),
    Op(char),
}

impl Tok {
    fn text(&self) -> String {
        match self {
            Tok::Num(x) => x.to_string(),
            Tok::Name(s) => s.clone(),
            Tok::Str(s) => format!("'{s}'"),
            Tok::Op(c) => c.to_string(),
        }
    }
}

fn lex(s: &str) -> Result<Vec<Tok>, ExprError> {
    let b = s.as_bytes();
    let mut i = 0;
    let mut out = Vec::new();
    while i < b.len() {
        let c = b[i] as char;
        if c.is_ascii_whitespace() {
            i += 1;
        } else if c.is_ascii_digit() || c == '.' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
                let save = i;
                i += 1;
                if i < b.len() && (b[i] == b'+' || b[i] == b'-') {
                    i += 1;
                }
                if i < b.len() && b[i].is_ascii_digit() {
                    while i < b.len() && b[i].is_ascii_digit() {
                        i += 1;
                    }
                } else {
                    i = save;
                }
            }
            let t = &s[start..i];
            out.push(Tok::Num(t.parse().map_err(|_| ExprError::Syntax {
                problem: format!("bad number `{t}`"),
                expr: s.trim().into(),
            })?));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            out.push(Tok::Name(s[start..i].to_string()));
        } else if c == '\'' {
            let start = i + 1;
            let end =
                s[start..]
                    .find('\'')
                    .map(|e| start + e)
                    .ok_or_else(|| ExprError::Syntax {
                        problem: "unterminated string".into(),
                        expr: s.trim().into(),
                    })?;
            out.push(Tok::Str(s[start..end].to_string()));
            i = end + 1;
        } else if "+-*/^(),[]".contains(c) {
            out.push(Tok::Op(c));
            i += 1;
        } else {
            return Err(ExprError::Syntax {
                problem: format!("unexpected character `{c}`"),
                expr: s.trim().into(),
            });
        }
    }
    Ok(out)
}

/// An intermediate value: expressions compute numbers, but names and literals may be
/// arrays or strings (as arguments of functions).
#[derive(Clone)]
enum V {
    Num(f64),
    Arr(Vec<f64>),
    Text(String),
    /// A boolean param or host-function result; 1 or 0 in arithmetic.
    Bool(bool),
}

impl V {
    fn number(self, src: &str) -> Result<f64, ExprError> {
        match self {
            V::Num(x) => Ok(x),
            V::Bool(b) => Ok(if b { 1.0 } else { 0.0 }),
            V::Arr(_) => Err(ExprError::Result {
                problem: "gives an array where a number is needed".into(),
                expr: src.trim().into(),
            }),
            V::Text(_) => Err(ExprError::Type {
                problem: "a string cannot be used in arithmetic".into(),
                expr: src.trim().into(),
            }),
        }
    }

    fn param(self) -> ParamValue {
        match self {
            V::Num(x) => ParamValue::Number(x),
            V::Arr(a) => ParamValue::Numbers(a),
            V::Text(t) => ParamValue::Text(t),
            V::Bool(b) => ParamValue::Bool(b),
        }
    }
}

/// How deeply an expression may nest (brackets, calls, unary signs): every level is
/// seven frames of the recursive-descent parser, over 8 KiB in a debug build (256 levels
/// overflowed a 2 MiB test thread; 50,000 overflowed the main thread); 64 fit with room.
pub const MAX_EXPR_NESTING: usize = 64;

/// An expression for an error message: its first 80 characters where it is longer
/// (a hostile one may be megabytes).
fn abbreviated(src: &str) -> String {
    let src = src.trim();
    match src.char_indices().nth(80) {
        Some((cut, _)) => format!("{}... ({} characters)", &src[..cut], src.len()),
        None => src.into(),
    }
}

struct Parser<'a> {
    src: &'a str,
    toks: Vec<Tok>,
    pos: usize,
    scope: &'a Scope<'a>,
    /// Levels of [`Parser::unary`] now open: every recursion of the grammar passes it.
    depth: usize,
}

impl Parser<'_> {
    fn peek_op(&self, c: char) -> bool {
        matches!(self.toks.get(self.pos), Some(Tok::Op(o)) if *o == c)
    }

    fn expect(&mut self, c: char) -> Result<(), ExprError> {
        if self.peek_op(c) {
            self.pos += 1;
            Ok(())
        } else {
            Err(ExprError::Syntax {
                problem: format!("expected `{c}`"),
                expr: self.src.trim().into(),
            })
        }
    }

    fn num(&mut self) -> Result<f64, ExprError> {
        let src = self.src;
        self.unary()?.number(src)
    }

    fn expr(&mut self) -> Result<V, ExprError> {
        let mut lhs = self.term()?;
        while self.peek_op('+') || self.peek_op('-') {
            let op = self.toks[self.pos].clone();
            self.pos += 1;
            let a = lhs.number(self.src)?;
            let b = self.term()?.number(self.src)?;
            lhs = V::Num(if op == Tok::Op('+') { a + b } else { a - b });
        }
        Ok(lhs)
    }

    fn term(&mut self) -> Result<V, ExprError> {
        let mut lhs = self.unary()?;
        while self.peek_op('*') || self.peek_op('/') {
            let op = self.toks[self.pos].clone();
            self.pos += 1;
            let a = lhs.number(self.src)?;
            let b = self.num()?;
            lhs = V::Num(if op == Tok::Op('*') { a * b } else { a / b });
        }
        Ok(lhs)
    }

    /// Every nesting of the grammar (a bracket, an argument list, an index, a sign)
    /// passes here, so the depth bound here bounds the parser's stack.
    fn unary(&mut self) -> Result<V, ExprError> {
        if self.depth >= MAX_EXPR_NESTING {
            return Err(ExprError::Syntax {
                problem: format!(
                    "nesting deeper than {MAX_EXPR_NESTING} levels (MAX_EXPR_NESTING)"
                ),
                expr: abbreviated(self.src),
            });
        }
        self.depth += 1;
        let v = self.unary_unbounded();
        self.depth -= 1;
        v
    }

    fn unary_unbounded(&mut self) -> Result<V, ExprError> {
        if self.peek_op('-') {
            self.pos += 1;
            let x = self.num()?;
            return Ok(V::Num(-x));
        }
        if self.peek_op('+') {
            self.pos += 1;
            return self.unary();
        }
        self.power()
    }

    fn power(&mut self) -> Result<V, ExprError> {
        let base = self.postfix()?;
        if self.peek_op('^') {
            self.pos += 1;
            let a = base.number(self.src)?;
            let b = self.num()?; // right-associative through unary -> power
            return Ok(V::Num(a.powf(b)));
        }
        Ok(base)
    }

    fn postfix(&mut self) -> Result<V, ExprError> {
        let mut v = self.atom()?;
        while self.peek_op('[') {
            self.pos += 1;
            let idx = self.expr()?.number(self.src)?;
            self.expect(']')?;
            let arr = match v {
                V::Arr(a) => a,
                _ => {
                    return Err(ExprError::Type {
                        problem: "indexing something that is not an array".into(),
                        expr: self.src.trim().into(),
                    });
                }
            };
            if idx < 0.0 || idx.fract() != 0.0 || idx as usize >= arr.len() {
                return Err(ExprError::Type {
                    problem: format!(
                        "index {idx} out of range for an array of length {}",
                        arr.len()
                    ),
                    expr: self.src.trim().into(),
                });
            }
            v = V::Num(arr[idx as usize]);
        }
        Ok(v)
    }

    fn list(&mut self, close: char) -> Result<Vec<V>, ExprError> {
        let mut items = Vec::new();
        if !self.peek_op(close) {
            loop {
                items.push(self.expr()?);
                if self.peek_op(',') {
                    self.pos += 1;
                } else {
                    break;
                }
            }
        }
        self.expect(close)?;
        Ok(items)
    }

    fn atom(&mut self) -> Result<V, ExprError> {
        let tok = self
            .toks
            .get(self.pos)
            .cloned()
            .ok_or_else(|| ExprError::Result {
                problem: "ends too early".into(),
                expr: self.src.trim().into(),
            })?;
        self.pos += 1;
        match tok {
            Tok::Num(x) => Ok(V::Num(x)),
            Tok::Str(s) => Ok(V::Text(s)),
            Tok::Op('(') => {
                let v = self.expr()?;
                self.expect(')')?;
                Ok(v)
            }
            Tok::Op('[') => {
                let src = self.src;
                let items = self.list(']')?;
                items
                    .into_iter()
                    .map(|v| v.number(src))
                    .collect::<Result<Vec<_>, _>>()
                    .map(V::Arr)
            }
            Tok::Name(name) => {
                if self.peek_op('(') {
                    self.pos += 1;
                    let args = self.list(')')?;
                    return self.call(&name, args);
                }
                if let Some(v) = self.scope.get(&name) {
                    return Ok(match v {
                        ParamValue::Number(x) => V::Num(*x),
                        ParamValue::Numbers(a) => V::Arr(a.clone()),
                        ParamValue::Bool(b) => V::Bool(*b),
                        ParamValue::Text(t) => V::Text(t.clone()),
                    });
                }
                if name == "pi" {
                    return Ok(V::Num(std::f64::consts::PI));
                }
                Err(self.scope.missing(&name, Some(self.src)))
            }
            Tok::Op(c) => Err(ExprError::Syntax {
                problem: format!("unexpected `{c}`"),
                expr: self.src.trim().into(),
            }),
        }
    }

    fn call(&self, name: &str, args: Vec<V>) -> Result<V, ExprError> {
        let src = self.src.trim();
        let misuse = |problem: String| ExprError::Type {
            problem,
            expr: src.into(),
        };
        let flat = |args: Vec<V>| -> Result<Vec<f64>, ExprError> {
            let mut out = Vec::new();
            for a in args {
                match a {
                    V::Num(x) => out.push(x),
                    V::Bool(b) => out.push(if b { 1.0 } else { 0.0 }),
                    V::Arr(v) => out.extend(v),
                    V::Text(_) => {
                        return Err(misuse(format!("`{name}` takes numbers")));
                    }
                }
            }
            Ok(out)
        };
        let unary = |args: Vec<V>, f: fn(f64) -> f64| -> Result<V, ExprError> {
            if args.len() != 1 {
                return Err(misuse(format!("`{name}` takes one argument")));
            }
            let x = args
                .into_iter()
                .next()
                .map(|a| a.number(src))
                .transpose()?
                .unwrap_or(0.0);
            Ok(V::Num(f(x)))
        };
        match name {
            "sqrt" => unary(args, f64::sqrt),
            "cbrt" => unary(args, f64::cbrt),
            "exp" => unary(args, f64::exp),
            "log" => unary(args, f64::ln),
            "log10" => unary(args, f64::log10),
            "sin" => unary(args, f64::sin),
            "cos" => unary(args, f64::cos),
            "tan" => unary(args, f64::tan),
            "atan" => unary(args, f64::atan),
            "abs" => unary(args, f64::abs),
            "floor" => unary(args, f64::floor),
            "ceil" => unary(args, f64::ceil),
            "round" => unary(args, f64::round),
            "eq" => {
                let [a, b]: [V; 2] = args
                    .try_into()
                    .map_err(|_| misuse("`eq` takes two arguments".into()))?;
                Ok(V::Bool(match (a, b) {
                    (V::Text(a), V::Text(b)) => a == b,
                    (V::Text(_), _) | (_, V::Text(_)) => {
                        return Err(misuse("`eq` compares a string with a string".into()));
                    }
                    (a, b) => flat(vec![a])? == flat(vec![b])?,
                }))
            }
            "pow" => {
                let v = flat(args)?;
                if v.len() != 2 {
                    return Err(misuse("`pow` takes two arguments".into()));
                }
                Ok(V::Num(v[0].powf(v[1])))
            }
            "min" | "max" | "sum" | "prod" => {
                let v = flat(args)?;
                if v.is_empty() {
                    return Err(misuse(format!("`{name}` needs at least one value")));
                }
                Ok(V::Num(match name {
                    "min" => v.iter().cloned().fold(f64::INFINITY, f64::min),
                    "max" => v.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
                    "sum" => v.iter().sum(),
                    _ => v.iter().product(),
                }))
            }
            _ => match self.scope.functions.get(name) {
                Some(f) => {
                    let params: Vec<ParamValue> = args.into_iter().map(V::param).collect();
                    let out = (f.call)(&params).map_err(|message| ExprError::Function {
                        name: name.into(),
                        message,
                        expr: src.into(),
                    })?;
                    Ok(match out {
                        ParamValue::Number(x) => V::Num(x),
                        ParamValue::Numbers(a) => V::Arr(a),
                        ParamValue::Text(t) => V::Text(t),
                        ParamValue::Bool(b) => V::Bool(b),
                    })
                }
                None => Err(ExprError::UnknownFunction {
                    name: name.into(),
                    expr: src.into(),
                }),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origins_follow_references_and_expressions_to_the_params_set() {
        let f = HostFunctions::default();
        let mut scope = Scope::new(&f);
        let radius = ParamValue::Number(5e-324);
        scope.insert_with_origin(
            "a".into(),
            radius.clone(),
            Origin::param("radius", &radius, true),
        );
        let box_ = ParamValue::Numbers(vec![8.0; 3]);
        scope.insert_with_origin("b".into(), box_.clone(), Origin::param("box", &box_, false));
        assert_eq!(names_read("max(a, b[0]) * pi + f(a)"), vec!["a", "b"]);
        let o = scope.origin_of(&serde_json::json!("= a * b[0]"));
        assert_eq!(
            o.describe().unwrap(),
            "computed from `radius` = 5e-324 via `a * b[0]`",
            "the params the user set are named, not their defaults"
        );
        let r = scope.origin_of(&serde_json::json!("$b"));
        assert_eq!(r.describe().unwrap(), "from graph param `box` = [8, 8, 8]");
        assert_eq!(scope.origin_of(&serde_json::json!(3.0)).describe(), None);
        assert_eq!(Origin::union([&o, &r]).sources.len(), 2);
    }

    /// A host function that answers with a boolean, as planners such as
    /// `fcm_sort_particles` do.
    fn functions() -> &'static HostFunctions {
        static F: std::sync::OnceLock<HostFunctions> = std::sync::OnceLock::new();
        F.get_or_init(|| {
            let mut f = HostFunctions::default();
            f.add(HostFunction {
                name: "larger_than_256",
                doc: "larger_than_256(x): whether x > 256",
                call: |a| match a.first() {
                    Some(ParamValue::Number(x)) => Ok(ParamValue::Bool(*x > 256.0)),
                    _ => Err("one number".into()),
                },
            });
            f
        })
    }

    fn scope() -> Scope<'static> {
        let mut s = Scope::new(functions());
        s.insert("dt".into(), ParamValue::Number(0.01));
        s.insert("temperature".into(), ParamValue::Number(2.0));
        s.insert("box".into(), ParamValue::Numbers(vec![64.0, 32.0, 16.0]));
        s.insert("kernel".into(), ParamValue::Text("gaussian".into()));
        s
    }

    #[test]
    fn eq_compares_strings_numbers_and_arrays() {
        let s = scope();
        for (text, want) in [
            ("eq(kernel, 'gaussian')", true),
            ("eq(kernel, 'es')", false),
            ("eq(dt, 0.01)", true),
            ("eq(box, [64, 32, 16])", true),
            ("eq(box, [64, 32])", false),
        ] {
            assert_eq!(
                evaluate(text, &s).unwrap(),
                ParamValue::Bool(want),
                "{text}"
            );
        }
        for bad in ["eq(kernel, 1)", "eq(kernel)"] {
            assert!(
                matches!(evaluate(bad, &s), Err(ExprError::Type { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn booleans_stay_booleans_and_count_as_0_or_1() {
        let mut s = scope();
        s.insert("rotation".into(), ParamValue::Bool(true));
        assert_eq!(evaluate("rotation", &s).unwrap(), ParamValue::Bool(true));
        assert_eq!(
            evaluate("1 + rotation", &s).unwrap(),
            ParamValue::Number(2.0)
        );
        assert_eq!(
            evaluate("larger_than_256(512)", &s).unwrap(),
            ParamValue::Bool(true)
        );
        assert_eq!(
            evaluate("larger_than_256(48) + 1", &s).unwrap(),
            ParamValue::Number(1.0)
        );
    }

    #[test]
    fn arithmetic_is_f64_not_integer() {
        let s = scope();
        assert_eq!(eval("2/3", &s).unwrap(), 2.0 / 3.0);
        assert_eq!(eval("1 + 2*3 - 4", &s).unwrap(), 3.0);
        assert_eq!(eval("2^3^2", &s).unwrap(), 512.0); // right-associative
        assert_eq!(eval("-2^2", &s).unwrap(), -4.0);
        assert_eq!(eval("1e-3 * 2E+2", &s).unwrap(), 0.2);
    }

    #[test]
    fn a_param_without_a_value_is_unresolved_but_unknown_names_come_first() {
        let mut s = scope();
        s.insert_unresolved("grid".into());
        let unresolved = ExprError::Unresolved {
            name: "grid".into(),
        };
        assert_eq!(eval("prod(grid) * dt", &s).unwrap_err(), unresolved);
        let json = serde_json::json!("$grid");
        assert_eq!(resolve(&json, &s).unwrap_err(), unresolved);
        // An unknown name is the expression's own problem, reported even beside one.
        assert!(matches!(
            eval("grid[0] * gird", &s).unwrap_err(),
            ExprError::UnknownName { name, known, .. } if name == "gird" && known.contains("grid")
        ));
        // A value given later resolves it.
        s.insert("grid".into(), ParamValue::Numbers(vec![2.0, 3.0]));
        assert_eq!(eval("prod(grid)", &s).unwrap(), 6.0);
    }

    #[test]
    fn names_functions_and_indexing() {
        let s = scope();
        assert!((eval("sqrt(2*temperature*dt)", &s).unwrap() - 0.2).abs() < 1e-15);
        assert_eq!(eval("box[1] / 2", &s).unwrap(), 16.0);
        assert_eq!(eval("prod(box)", &s).unwrap(), 64.0 * 32.0 * 16.0);
        assert_eq!(eval("max(box, 100)", &s).unwrap(), 100.0);
        assert_eq!(eval("pi", &s).unwrap(), std::f64::consts::PI);
    }

    #[test]
    fn errors_name_the_problem() {
        let s = scope();
        assert!(
            eval("viscosity * 2", &s)
                .unwrap_err()
                .to_string()
                .contains("unknown param `viscosity`")
        );
        assert!(
            eval("box[3]", &s)
                .unwrap_err()
                .to_string()
                .contains("out of range")
        );
        assert!(eval("box", &s).unwrap_err().to_string().contains("array"));
        assert!(
            eval("kernel + 1", &s)
                .unwrap_err()
                .to_string()
                .contains("string")
        );
        assert!(
            eval("'a", &s)
                .unwrap_err()
                .to_string()
                .contains("unterminated")
        );
        assert!(
            eval("1 +", &s)
                .unwrap_err()
                .to_string()
                .contains("ends too early")
        );
        assert!(
            eval("(1", &s)
                .unwrap_err()
                .to_string()
                .contains("expected `)`")
        );
        assert!(
            eval("1/0", &s)
                .unwrap_err()
                .to_string()
                .contains("not finite")
        );
        assert!(
            eval("foo(1)", &s)
                .unwrap_err()
                .to_string()
                .contains("unknown function")
        );
        assert!(
            eval("1 # 2", &s)
                .unwrap_err()
                .to_string()
                .contains("unexpected character")
        );
    }

    #[test]
    fn resolve_literals_references_expressions() {
        let s = scope();
        let j = |t: &str| serde_json::from_str::<serde_json::Value>(t).unwrap();
        assert_eq!(resolve(&j("0.5"), &s).unwrap(), ParamValue::Number(0.5));
        assert_eq!(
            resolve(&j("\"$kernel\""), &s).unwrap(),
            ParamValue::Text("gaussian".into())
        );
        assert_eq!(
            resolve(&j("\"$box\""), &s).unwrap(),
            ParamValue::Numbers(vec![64.0, 32.0, 16.0])
        );
        assert_eq!(
            resolve(&j("\"= dt * 100\""), &s).unwrap(),
            ParamValue::Number(1.0)
        );
        assert_eq!(
            resolve(&j("\"es\""), &s).unwrap(),
            ParamValue::Text("es".into())
        );
        assert!(resolve(&j("\"$nope\""), &s).is_err());
        assert!(resolve(&j("null"), &s).is_err());
    }

    #[test]
    fn arrays_and_strings() {
        let s = scope();
        assert_eq!(
            evaluate("[1, 2 * 3, box[2]]", &s).unwrap(),
            ParamValue::Numbers(vec![1.0, 6.0, 16.0])
        );
        assert_eq!(evaluate("[]", &s).unwrap(), ParamValue::Numbers(vec![]));
        assert!(
            evaluate("kernel", &s)
                .unwrap_err()
                .to_string()
                .contains("gives a string")
        );
        assert!(
            evaluate("['a']", &s)
                .unwrap_err()
                .to_string()
                .contains("arithmetic")
        );
        assert!(
            eval("larger_than_256('x')", &s)
                .unwrap_err()
                .to_string()
                .contains("larger_than_256: one number")
        );
    }

    #[test]
    fn cli_values() {
        assert_eq!(ParamValue::from_cli("3").unwrap(), ParamValue::Number(3.0));
        assert_eq!(
            ParamValue::from_cli("[64,64,32]").unwrap(),
            ParamValue::Numbers(vec![64.0, 64.0, 32.0])
        );
        assert_eq!(
            ParamValue::from_cli("es").unwrap(),
            ParamValue::Text("es".into())
        );
        assert_eq!(
            ParamValue::from_cli("true").unwrap(),
            ParamValue::Bool(true)
        );
        assert!(ParamValue::from_cli("[1, \"a\"]").is_err());
    }

    /// Expressions nested 100,000 deep (brackets, signs, calls, arrays) are an error
    /// naming the limit, not a stack overflow; the limit itself still parses.
    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let s = scope();
        let deep = 100_000;
        for text in [
            format!("{}1{}", "(".repeat(deep), ")".repeat(deep)),
            format!("{}1", "-".repeat(deep)),
            format!("{}1", "+".repeat(deep)),
            format!("{}1{}", "sqrt(".repeat(deep), ")".repeat(deep)),
            format!("{}1{}", "[".repeat(deep), "]".repeat(deep)),
            format!("2{}", "^2".repeat(deep)),
        ] {
            let e = evaluate(&text, &s).unwrap_err().to_string();
            assert!(e.contains("MAX_EXPR_NESTING"), "{e}");
            assert!(
                e.len() < 300,
                "the message quotes the whole expression: {}",
                e.len()
            );
        }
        let ok = MAX_EXPR_NESTING - 1;
        let text = format!("{}1{}", "(".repeat(ok), ")".repeat(ok));
        assert_eq!(eval(&text, &s).unwrap(), 1.0);
    }

    #[test]
    fn overrides() {
        let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let parsed = parse_overrides(&args(&["box=[64,64,32]", " dt =0.5"])).unwrap();
        assert_eq!(parsed["box"], ParamValue::Numbers(vec![64.0, 64.0, 32.0]));
        assert_eq!(parsed["dt"], ParamValue::Number(0.5));
        assert_eq!(
            parse_overrides(&args(&["dt"])),
            Err(OverrideError::Malformed("dt".into()))
        );
        assert_eq!(
            parse_overrides(&args(&["=1"])),
            Err(OverrideError::Malformed("=1".into()))
        );
        assert_eq!(
            parse_overrides(&args(&["dt=1", "dt=2"])),
            Err(OverrideError::Repeated("dt".into()))
        );
        assert!(matches!(
            parse_overrides(&args(&["box=[1,"])),
            Err(OverrideError::Value { name, .. }) if name == "box"
        ));
    }
}
