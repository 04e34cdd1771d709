//! pbrt-v3's syntax: the tokenizer (words, numbers, quoted strings,
//! brackets, comments; each token with its line) and a directive's
//! `"type name" value` parameter list.

use std::collections::HashMap;

use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub(super) enum Token {
    Str(String),
    Num(f64),
    Word(String),
    Open,
    Close,
}

pub(super) fn tokenize(text: &str) -> Result<Vec<(Token, usize)>, (usize, String)> {
    // A control character (a NUL from a damaged file) would end a word
    // where none ends, and its directive be skipped as unknown.
    if let Some(at) = text.find(|c: char| c.is_control() && !c.is_whitespace()) {
        let line = 1 + text[..at].matches('\n').count();
        let c = text[at..].chars().next().unwrap_or_default();
        return Err((line, format!("a control character (U+{:04X})", c as u32)));
    }
    let mut out = Vec::new();
    let mut chars = text.char_indices().peekable();
    let mut line = 1;
    while let Some(&(_, c)) = chars.peek() {
        match c {
            '\n' => {
                line += 1;
                chars.next();
            }
            c if c.is_whitespace() => {
                chars.next();
            }
            '#' => {
                while chars.peek().is_some_and(|&(_, c)| c != '\n') {
                    chars.next();
                }
            }
            '[' => {
                out.push((Token::Open, line));
                chars.next();
            }
            ']' => {
                out.push((Token::Close, line));
                chars.next();
            }
            '"' => {
                chars.next();
                let mut s = String::new();
                loop {
                    match chars.next() {
                        Some((_, '"')) => break,
                        Some((_, '\n')) | None => return Err((line, "unterminated string".into())),
                        Some((_, c)) => s.push(c),
                    }
                }
                out.push((Token::Str(s), line));
            }
            _ => {
                let mut word = String::new();
                while let Some(&(_, c)) = chars.peek() {
                    if c.is_whitespace() || c == '[' || c == ']' || c == '"' || c == '#' {
                        break;
                    }
                    word.push(c);
                    chars.next();
                }
                let token = match word.parse::<f64>() {
                    Ok(v) => Token::Num(v),
                    Err(_) if word.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) => {
                        Token::Word(word)
                    }
                    Err(_) => return Err((line, format!("unexpected `{word}`"))),
                };
                out.push((token, line));
            }
        }
    }
    Ok(out)
}

/// A parameter value.
#[derive(Clone, Debug)]
pub(super) enum Value {
    Nums(Vec<f64>),
    Strs(Vec<String>),
}

/// `"type name" value` pairs.
#[derive(Clone, Debug, Default)]
pub(super) struct Params(pub(super) HashMap<String, (String, Value)>);

impl Params {
    pub(super) fn nums(&self, name: &str) -> Option<&[f64]> {
        match self.0.get(name) {
            Some((_, Value::Nums(v))) => Some(v),
            _ => None,
        }
    }
    pub(super) fn num(&self, name: &str) -> Option<f64> {
        self.nums(name).and_then(|v| v.first().copied())
    }
    pub(super) fn string(&self, name: &str) -> Option<&str> {
        match self.0.get(name) {
            Some((_, Value::Strs(v))) => v.first().map(String::as_str),
            _ => None,
        }
    }
    pub(super) fn bool(&self, name: &str) -> Option<bool> {
        self.string(name).map(|s| s == "true")
    }
    pub(super) fn ty(&self, name: &str) -> Option<&str> {
        self.0.get(name).map(|(t, _)| t.as_str())
    }
    pub(super) fn rgb(&self, name: &str) -> Option<Vec3> {
        self.nums(name).and_then(|v| match v {
            [r, g, b, ..] => Some(Vec3::new(*r as f32, *g as f32, *b as f32)),
            [v] => Some(Vec3::splat(*v as f32)),
            _ => None,
        })
    }
}
