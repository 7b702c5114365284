//! The expression language of user effects: a small parser (precedence climbing) to a
//! syntax tree, symbolic derivatives with respect to linear coefficients, and a compiler to
//! a postfix program evaluated on a fixed-size stack (no allocation per sample).
//!
//! Written here rather than taken from a crate: the candidates (`evalexpr`, `meval`,
//! `fasteval`, `exmex`) either evaluate through dynamically typed values that allocate, are
//! no longer kept, or report errors without the column; crosscal needs the column of every
//! error inside the user's TOML file, two-argument `max`/`min`/`pow`, and a structural
//! affinity check of each coefficient (its derivative must not depend on any coefficient).
//!
//! Grammar (usual precedence, `^` binds tighter than unary minus and is right-associative,
//! so `-x^2` is `-(x^2)`; a number directly followed by a name multiplies it, `4 deg`):
//! ```text
//! sum     := product (('+' | '-') product)*
//! product := unary (('*' | '/') unary)*
//! unary   := '-' unary | power
//! power   := atom ('^' unary)?
//! atom    := number [name] | name | name '(' sum (',' sum)* ')' | '(' sum ')'
//! ```

use std::fmt;

/// The variables an expression may read, in slot order: true inputs in sensor axes (SI).
pub const VARIABLES: [&str; 12] = ["w_x", "w_y", "w_z", "e_x", "e_y", "e_z", "a_x", "a_y", "a_z", "T", "dTdt", "t"];

/// Functions: name and number of arguments.
pub const FUNCTIONS: [(&str, usize); 10] = [
    ("abs", 1),
    ("sign", 1),
    ("max", 2),
    ("min", 2),
    ("sqrt", 1),
    ("exp", 1),
    ("ln", 1),
    ("sin", 1),
    ("cos", 1),
    ("pow", 2),
];

/// Named constants.
pub const CONSTANTS: [(&str, f64); 2] = [("deg", std::f64::consts::PI / 180.0), ("pi", std::f64::consts::PI)];

/// Largest number of slots (variables, coefficients and parameters) of one expression.
pub const MAX_SLOTS: usize = 32;
/// Deepest evaluation stack a program may need.
pub const MAX_STACK: usize = 32;

/// A parse or compile error at a character offset of the expression.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExprError {
    /// Character offset in the expression (0-based).
    pub pos: usize,
    /// What was found and what was expected.
    pub msg: String,
}

impl fmt::Display for ExprError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.msg)
    }
}

/// A function of the language.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Func {
    /// |x|
    Abs,
    /// sign(x) (0 at 0)
    Sign,
    /// max(x, y)
    Max,
    /// min(x, y)
    Min,
    /// √x
    Sqrt,
    /// eˣ
    Exp,
    /// ln x
    Ln,
    /// sin x
    Sin,
    /// cos x
    Cos,
    /// xʸ
    Pow,
}

impl Func {
    fn from_index(i: usize) -> Self {
        [Self::Abs, Self::Sign, Self::Max, Self::Min, Self::Sqrt, Self::Exp, Self::Ln, Self::Sin, Self::Cos, Self::Pow]
            [i]
    }
}

/// A syntax tree node.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// A number.
    Num(f64),
    /// A slot (variable, coefficient or parameter).
    Slot(usize),
    /// −a
    Neg(Box<Node>),
    /// a + b
    Add(Box<Node>, Box<Node>),
    /// a − b
    Sub(Box<Node>, Box<Node>),
    /// a · b
    Mul(Box<Node>, Box<Node>),
    /// a / b
    Div(Box<Node>, Box<Node>),
    /// A function call (`^` is `pow`).
    Call(Func, Vec<Node>),
}

struct Parser<'a> {
    chars: Vec<char>,
    pos: usize,
    names: &'a [&'a str],
}

impl Parser<'_> {
    fn skip_ws(&mut self) {
        while self.chars.get(self.pos).is_some_and(|c| c.is_whitespace()) {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<char> {
        self.skip_ws();
        self.chars.get(self.pos).copied()
    }

    fn err<T>(&self, pos: usize, msg: impl Into<String>) -> Result<T, ExprError> {
        Err(ExprError { pos, msg: msg.into() })
    }

    fn found(&mut self) -> String {
        match self.peek() {
            Some(c) => format!("'{c}'"),
            None => "the end of the expression".into(),
        }
    }

    fn sum(&mut self) -> Result<Node, ExprError> {
        let mut a = self.product()?;
        while let Some(c @ ('+' | '-')) = self.peek() {
            self.pos += 1;
            let b = self.product()?;
            a = if c == '+' { Node::Add(a.into(), b.into()) } else { Node::Sub(a.into(), b.into()) };
        }
        Ok(a)
    }

    fn product(&mut self) -> Result<Node, ExprError> {
        let mut a = self.unary()?;
        while let Some(c @ ('*' | '/')) = self.peek() {
            self.pos += 1;
            let b = self.unary()?;
            a = if c == '*' { Node::Mul(a.into(), b.into()) } else { Node::Div(a.into(), b.into()) };
        }
        Ok(a)
    }

    fn unary(&mut self) -> Result<Node, ExprError> {
        if self.peek() == Some('-') {
            self.pos += 1;
            return Ok(Node::Neg(self.unary()?.into()));
        }
        if self.peek() == Some('+') {
            self.pos += 1;
            return self.unary();
        }
        self.power()
    }

    fn power(&mut self) -> Result<Node, ExprError> {
        let a = self.atom()?;
        if self.peek() == Some('^') {
            self.pos += 1;
            let b = self.unary()?;
            return Ok(Node::Call(Func::Pow, vec![a, b]));
        }
        Ok(a)
    }

    fn name(&mut self) -> String {
        let start = self.pos;
        while self.chars.get(self.pos).is_some_and(|c| c.is_alphanumeric() || *c == '_') {
            self.pos += 1;
        }
        self.chars[start..self.pos].iter().collect()
    }

    fn number(&mut self) -> Result<f64, ExprError> {
        let start = self.pos;
        let digits = |p: &mut Self| {
            while p.chars.get(p.pos).is_some_and(char::is_ascii_digit) {
                p.pos += 1;
            }
        };
        digits(self);
        if self.chars.get(self.pos) == Some(&'.') {
            self.pos += 1;
            digits(self);
        }
        if matches!(self.chars.get(self.pos), Some('e' | 'E'))
            && self.chars.get(self.pos + 1).is_some_and(|c| c.is_ascii_digit() || *c == '-' || *c == '+')
        {
            self.pos += 2;
            digits(self);
        }
        let text: String = self.chars[start..self.pos].iter().collect();
        text.parse::<f64>().or_else(|_| self.err(start, format!("'{text}' is not a number")))
    }

    fn atom(&mut self) -> Result<Node, ExprError> {
        let Some(c) = self.peek() else {
            return self.err(self.pos, "expected a number, a name or '(' but found the end of the expression");
        };
        let start = self.pos;
        if c.is_ascii_digit() || c == '.' {
            let v = self.number()?;
            // `4 deg`: a number directly followed by a name multiplies it.
            if self.peek().is_some_and(|c| c.is_alphabetic()) {
                let unit = self.atom()?;
                return Ok(Node::Mul(Node::Num(v).into(), unit.into()));
            }
            return Ok(Node::Num(v));
        }
        if c == '(' {
            self.pos += 1;
            let e = self.sum()?;
            if self.peek() != Some(')') {
                let found = self.found();
                return self
                    .err(self.pos, format!("expected ')' to close the '(' at column {} but found {found}", start + 1));
            }
            self.pos += 1;
            return Ok(e);
        }
        if !(c.is_alphabetic() || c == '_') {
            return self.err(start, format!("expected a number, a name or '(' but found '{c}'"));
        }
        let name = self.name();
        if self.peek() == Some('(') {
            return self.call(&name, start);
        }
        if let Some(i) = self.names.iter().position(|n| *n == name) {
            return Ok(Node::Slot(i));
        }
        if let Some((_, v)) = CONSTANTS.iter().find(|(n, _)| *n == name) {
            return Ok(Node::Num(*v));
        }
        let what = if FUNCTIONS.iter().any(|(f, _)| *f == name) {
            format!("'{name}' is a function: write {name}(…)")
        } else {
            format!(
                "unknown name '{name}': expected a variable ({}), a constant (deg, pi) or one of the effect's coefficients or parameters{}",
                VARIABLES.join(", "),
                self.extra_names()
            )
        };
        self.err(start, what)
    }

    fn extra_names(&self) -> String {
        let own: Vec<&str> = self.names.iter().skip(VARIABLES.len()).copied().collect();
        if own.is_empty() {
            String::new()
        } else {
            format!(" ({})", own.join(", "))
        }
    }

    fn call(&mut self, name: &str, start: usize) -> Result<Node, ExprError> {
        let Some(fi) = FUNCTIONS.iter().position(|(f, _)| *f == name) else {
            let known: Vec<&str> = FUNCTIONS.iter().map(|(f, _)| *f).collect();
            return self.err(start, format!("unknown function '{name}': expected one of {}", known.join(", ")));
        };
        self.pos += 1; // '('
        let mut args = vec![self.sum()?];
        while self.peek() == Some(',') {
            self.pos += 1;
            args.push(self.sum()?);
        }
        if self.peek() != Some(')') {
            let found = self.found();
            return self.err(self.pos, format!("expected ',' or ')' in the call of {name} but found {found}"));
        }
        self.pos += 1;
        let want = FUNCTIONS[fi].1;
        if args.len() != want {
            return self.err(start, format!("{name} takes {want} argument(s), found {}", args.len()));
        }
        Ok(Node::Call(Func::from_index(fi), args))
    }
}

/// Parses `text`; `names` are the slots in order (the [`VARIABLES`] first, then the
/// effect's coefficients and parameters).
pub fn parse(text: &str, names: &[&str]) -> Result<Node, ExprError> {
    let mut p = Parser { chars: text.chars().collect(), pos: 0, names };
    if p.peek().is_none() {
        return p.err(0, "the expression is empty: expected a formula such as 'k * w_x'");
    }
    let n = p.sum()?;
    if p.peek().is_some() {
        let found = p.found();
        return p.err(p.pos, format!("expected an operator (+ - * / ^) or the end but found {found}"));
    }
    Ok(n)
}

impl Node {
    /// Whether the tree reads slot `s`.
    pub fn uses(&self, s: usize) -> bool {
        match self {
            Self::Num(_) => false,
            Self::Slot(i) => *i == s,
            Self::Neg(a) => a.uses(s),
            Self::Add(a, b) | Self::Sub(a, b) | Self::Mul(a, b) | Self::Div(a, b) => a.uses(s) || b.uses(s),
            Self::Call(_, args) => args.iter().any(|a| a.uses(s)),
        }
    }

    /// Whether the tree reads any slot in `range`.
    pub fn uses_any(&self, range: std::ops::Range<usize>) -> bool {
        range.into_iter().any(|s| self.uses(s))
    }

    /// ∂/∂(slot s), for a tree in which slot s enters only through sums, products with
    /// factors free of it and numerators (else the slot enters nonlinearly: None).
    pub fn derivative(&self, s: usize) -> Option<Node> {
        if !self.uses(s) {
            return Some(Node::Num(0.0));
        }
        Some(match self {
            Self::Num(_) => Node::Num(0.0),
            Self::Slot(_) => Node::Num(1.0),
            Self::Neg(a) => Node::Neg(a.derivative(s)?.into()).simplify(),
            Self::Add(a, b) => Node::Add(a.derivative(s)?.into(), b.derivative(s)?.into()).simplify(),
            Self::Sub(a, b) => Node::Sub(a.derivative(s)?.into(), b.derivative(s)?.into()).simplify(),
            Self::Mul(a, b) => match (a.uses(s), b.uses(s)) {
                (true, false) => Node::Mul(a.derivative(s)?.into(), b.clone()).simplify(),
                (false, true) => Node::Mul(a.clone(), b.derivative(s)?.into()).simplify(),
                _ => return None,
            },
            Self::Div(a, b) if !b.uses(s) => Node::Div(a.derivative(s)?.into(), b.clone()).simplify(),
            _ => return None,
        })
    }

    /// The tree with slot `s` replaced by the number `v`, simplified.
    pub fn substitute(&self, s: usize, v: f64) -> Node {
        match self {
            Self::Num(_) => self.clone(),
            Self::Slot(i) if *i == s => Node::Num(v),
            Self::Slot(_) => self.clone(),
            Self::Neg(a) => Node::Neg(a.substitute(s, v).into()),
            Self::Add(a, b) => Node::Add(a.substitute(s, v).into(), b.substitute(s, v).into()),
            Self::Sub(a, b) => Node::Sub(a.substitute(s, v).into(), b.substitute(s, v).into()),
            Self::Mul(a, b) => Node::Mul(a.substitute(s, v).into(), b.substitute(s, v).into()),
            Self::Div(a, b) => Node::Div(a.substitute(s, v).into(), b.substitute(s, v).into()),
            Self::Call(f, args) => Node::Call(*f, args.iter().map(|a| a.substitute(s, v)).collect()),
        }
        .simplify()
    }

    /// Folds constants and the identities 0 + x, x · 1, 0 · x, 0 / x, −0.
    pub fn simplify(self) -> Node {
        use Node::*;
        match self {
            Neg(a) => match a.simplify() {
                Num(v) => Num(-v),
                a => Neg(a.into()),
            },
            Add(a, b) => match (a.simplify(), b.simplify()) {
                (Num(x), Num(y)) => Num(x + y),
                (Num(0.0), e) | (e, Num(0.0)) => e,
                (a, b) => Add(a.into(), b.into()),
            },
            Sub(a, b) => match (a.simplify(), b.simplify()) {
                (Num(x), Num(y)) => Num(x - y),
                (e, Num(0.0)) => e,
                (Num(0.0), e) => Neg(e.into()),
                (a, b) => Sub(a.into(), b.into()),
            },
            Mul(a, b) => match (a.simplify(), b.simplify()) {
                (Num(x), Num(y)) => Num(x * y),
                (Num(z), _) | (_, Num(z)) if z == 0.0 => Num(0.0),
                (Num(o), e) | (e, Num(o)) if o.to_bits() == 1.0f64.to_bits() => e,
                (a, b) => Mul(a.into(), b.into()),
            },
            Div(a, b) => match (a.simplify(), b.simplify()) {
                (Num(x), Num(y)) if y != 0.0 => Num(x / y),
                (Num(0.0), _) => Num(0.0),
                (e, Num(o)) if o.to_bits() == 1.0f64.to_bits() => e,
                (a, b) => Div(a.into(), b.into()),
            },
            Call(f, args) => {
                let args: Vec<Node> = args.into_iter().map(Node::simplify).collect();
                if args.iter().all(|a| matches!(a, Num(_))) {
                    let mut p = Program { ops: Vec::new() };
                    p.emit(&Call(f, args.clone()));
                    return Num(p.eval(&[]));
                }
                Call(f, args)
            }
            n => n,
        }
    }
}

/// One instruction of a compiled expression.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Op {
    Num(f64),
    Slot(u8),
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    /// `x^n` for a small integer constant `n` (by multiplication: `powf` dominated the
    /// fit's time on `w_x^2`).
    PowI(i32),
    Func(Func),
}

/// A compiled expression: postfix instructions run on a fixed-size stack.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    ops: Vec<Op>,
}

impl Program {
    /// Compiles a tree (slots must be below [`MAX_SLOTS`]; the stack depth is checked).
    pub fn compile(n: &Node) -> Result<Self, ExprError> {
        let mut p = Program { ops: Vec::new() };
        p.emit(n);
        let mut depth = 0usize;
        let mut deepest = 0usize;
        for op in &p.ops {
            match op {
                Op::Num(_) | Op::Slot(_) => depth += 1,
                Op::Neg
                | Op::PowI(_)
                | Op::Func(Func::Abs | Func::Sign | Func::Sqrt | Func::Exp | Func::Ln | Func::Sin | Func::Cos) => {}
                _ => depth -= 1,
            }
            deepest = deepest.max(depth);
        }
        if deepest > MAX_STACK {
            return Err(ExprError { pos: 0, msg: format!("the expression nests deeper than {MAX_STACK} levels") });
        }
        Ok(p)
    }

    fn emit(&mut self, n: &Node) {
        match n {
            Node::Num(v) => self.ops.push(Op::Num(*v)),
            Node::Slot(i) => self.ops.push(Op::Slot(*i as u8)),
            Node::Neg(a) => {
                self.emit(a);
                self.ops.push(Op::Neg);
            }
            Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
                self.emit(a);
                self.emit(b);
                self.ops.push(match n {
                    Node::Add(..) => Op::Add,
                    Node::Sub(..) => Op::Sub,
                    Node::Mul(..) => Op::Mul,
                    _ => Op::Div,
                });
            }
            Node::Call(Func::Pow, args) if args.len() == 2 && small_integer(&args[1]).is_some() => {
                self.emit(&args[0]);
                self.ops.push(Op::PowI(small_integer(&args[1]).unwrap_or(1)));
            }
            Node::Call(f, args) => {
                for a in args {
                    self.emit(a);
                }
                self.ops.push(Op::Func(*f));
            }
        }
    }

    /// Whether the program is the constant 0.
    pub fn is_zero(&self) -> bool {
        matches!(self.ops.as_slice(), [Op::Num(z)] if *z == 0.0)
    }

    /// The value with the slots' values `slots` (missing slots read NaN). Runs on a stack
    /// array: nothing is allocated.
    #[inline]
    pub fn eval(&self, slots: &[f64]) -> f64 {
        self.run(|i| slots.get(i).copied().unwrap_or(f64::NAN))
    }

    /// The value with the variables `vars` (slots 0..12, [`VARIABLES`]) and the further
    /// slots (coefficients, then parameters) in `extra`; missing slots read NaN. What the
    /// per-sample regressors call: no slot array is assembled.
    #[inline]
    pub fn eval_parts(&self, vars: &[f64; VARIABLES.len()], extra: &[f64]) -> f64 {
        self.run(|i| match vars.get(i) {
            Some(v) => *v,
            None => extra.get(i - VARIABLES.len()).copied().unwrap_or(f64::NAN),
        })
    }

    #[inline(always)]
    fn run(&self, slot: impl Fn(usize) -> f64) -> f64 {
        let mut st = [0.0f64; MAX_STACK];
        let mut n = 0usize;
        for op in &self.ops {
            match *op {
                Op::Num(v) => {
                    st[n] = v;
                    n += 1;
                }
                Op::Slot(i) => {
                    st[n] = slot(usize::from(i));
                    n += 1;
                }
                Op::Neg => st[n - 1] = -st[n - 1],
                Op::PowI(k) => {
                    let x = st[n - 1];
                    st[n - 1] = match k {
                        2 => x * x,
                        3 => x * x * x,
                        _ => x.powi(k),
                    };
                }
                Op::Func(f @ (Func::Abs | Func::Sign | Func::Sqrt | Func::Exp | Func::Ln | Func::Sin | Func::Cos)) => {
                    let x = st[n - 1];
                    st[n - 1] = match f {
                        Func::Abs => x.abs(),
                        Func::Sign => {
                            if x > 0.0 {
                                1.0
                            } else if x < 0.0 {
                                -1.0
                            } else {
                                0.0
                            }
                        }
                        Func::Sqrt => x.sqrt(),
                        Func::Exp => x.exp(),
                        Func::Ln => x.ln(),
                        Func::Sin => x.sin(),
                        _ => x.cos(),
                    };
                }
                op => {
                    let (a, b) = (st[n - 2], st[n - 1]);
                    n -= 1;
                    st[n - 1] = match op {
                        Op::Add => a + b,
                        Op::Sub => a - b,
                        Op::Mul => a * b,
                        Op::Div => a / b,
                        Op::Func(Func::Max) => a.max(b),
                        Op::Func(Func::Min) => a.min(b),
                        _ => a.powf(b),
                    };
                }
            }
        }
        if n == 0 {
            f64::NAN
        } else {
            st[n - 1]
        }
    }
}

/// `n` when the node is an integer constant with |n| ≤ 64 (compiled to [`Op::PowI`]).
fn small_integer(n: &Node) -> Option<i32> {
    match n {
        Node::Num(v) if v.fract() == 0.0 && v.abs() <= 64.0 => Some(*v as i32),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<&'static str> {
        let mut v = VARIABLES.to_vec();
        v.extend(["k", "w0"]);
        v
    }

    fn eval(text: &str, slots: &[f64]) -> f64 {
        Program::compile(&parse(text, &names()).unwrap()).unwrap().eval(slots)
    }

    #[test]
    fn precedence_and_functions() {
        let mut s = [0.0; 14];
        s[0] = 2.0; // w_x
        s[12] = 3.0; // k
        assert!((eval("1 + 2 * 3 ^ 2", &s) - 19.0).abs() < 1e-12);
        assert!((eval("-w_x^2", &s) + 4.0).abs() < 1e-12);
        assert!((eval("2^3^2", &s) - 512.0).abs() < 1e-9);
        assert!((eval("k * max(w_x - 1, 0) + min(-1, sign(-w_x))", &s) - 2.0).abs() < 1e-12);
        assert!((eval("4 deg", &s) - 4.0f64.to_radians()).abs() < 1e-15);
        assert!((eval("pow(w_x, 0.5) - sqrt(2)", &s)).abs() < 1e-15);
        assert!((eval("ln(exp(1)) + sin(0) + cos(0) + abs(-2)", &s) - 4.0).abs() < 1e-15);
    }

    /// Integer powers run as multiplications (`Op::PowI`) and agree with `powf`; other
    /// exponents stay `powf`; `eval_parts` reads the same slots as `eval`.
    #[test]
    fn integer_powers_and_split_slots() {
        for x in [-2.5f64, -1.0, 0.0, 0.3, 7.0] {
            let mut s = [0.0; 14];
            s[0] = x;
            s[12] = 1.5;
            for (text, want) in [
                ("w_x^2", x * x),
                ("w_x^3", x * x * x),
                ("pow(w_x, 5)", x.powf(5.0)),
                ("w_x^-1", x.powf(-1.0)),
                ("w_x^0", 1.0),
                ("abs(w_x)^1.5", x.abs().powf(1.5)),
                ("k * w_x^2", 1.5 * x * x),
            ] {
                let got = eval(text, &s);
                assert!(
                    got.to_bits() == want.to_bits() || (got - want).abs() <= 1e-15 * want.abs(),
                    "{text} at {x}: {got} vs {want}"
                );
                let p = Program::compile(&parse(text, &names()).unwrap()).unwrap();
                let mut vars = [0.0; 12];
                vars.copy_from_slice(&s[..12]);
                let split = p.eval_parts(&vars, &s[12..]);
                assert!(split.to_bits() == got.to_bits(), "{text}: {split} vs {got}");
            }
        }
        let p = Program::compile(&parse("w_x^2", &names()).unwrap()).unwrap();
        assert!(p.ops.contains(&Op::PowI(2)), "{:?}", p.ops);
        let p = Program::compile(&parse("w_x^0.5", &names()).unwrap()).unwrap();
        assert!(p.ops.contains(&Op::Func(Func::Pow)), "{:?}", p.ops);
    }

    #[test]
    fn errors_name_the_column_and_what_was_expected() {
        let e = parse("k * w_q", &names()).unwrap_err();
        assert_eq!(e.pos, 4);
        assert!(e.msg.contains("unknown name 'w_q'") && e.msg.contains("w_x"), "{}", e.msg);
        let e = parse("k * foo(w_x)", &names()).unwrap_err();
        assert!(e.msg.contains("unknown function 'foo'"), "{}", e.msg);
        let e = parse("k * (w_x + 1", &names()).unwrap_err();
        assert_eq!(e.pos, 12);
        assert!(e.msg.contains("expected ')'"), "{}", e.msg);
        let e = parse("k w_x", &names()).unwrap_err();
        assert_eq!(e.pos, 2);
        let e = parse("max(w_x)", &names()).unwrap_err();
        assert!(e.msg.contains("takes 2"), "{}", e.msg);
    }

    #[test]
    fn derivative_of_an_affine_coefficient_and_refusal_of_a_nonlinear_one() {
        let n = parse("k * max(w_x - w0, 0) + 0.5", &names()).unwrap();
        let d = n.derivative(12).unwrap();
        assert!(!d.uses(12));
        let p = Program::compile(&d).unwrap();
        let mut s = [0.0; 14];
        s[0] = 3.0;
        s[13] = 1.0;
        assert!((p.eval(&s) - 2.0).abs() < 1e-12);
        assert!(parse("k * k * w_x", &names()).unwrap().derivative(12).is_none());
        assert!(parse("abs(k * w_x)", &names()).unwrap().derivative(12).is_none());
        assert!(parse("w_x / k", &names()).unwrap().derivative(12).is_none());
        assert_eq!(parse("w_x", &names()).unwrap().derivative(12), Some(Node::Num(0.0)));
        // The part without the coefficient.
        assert_eq!(parse("k * w_x", &names()).unwrap().substitute(12, 0.0), Node::Num(0.0));
    }
}
