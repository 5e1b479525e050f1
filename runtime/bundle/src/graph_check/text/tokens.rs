//! NNEF's tokens, read one at a time with their line numbers, no allocation and no recursion.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Token<'a> {
    Ident(&'a str),
    Number(&'a str),
    Str,
    Punct(u8),
    Arrow,
}

/// Tokens of `text` with their 1-based lines; `Err(line)` at the first byte that is no token.
pub(super) fn tokens(text: &str) -> impl Iterator<Item = Result<(usize, Token<'_>), usize>> {
    let bytes = text.as_bytes();
    let mut at = 0usize;
    let mut line = 1usize;
    std::iter::from_fn(move || {
        loop {
            match bytes.get(at)? {
                b'\n' => {
                    line += 1;
                    at += 1;
                }
                b' ' | b'\t' | b'\r' => at += 1,
                b'#' => {
                    while bytes.get(at).is_some_and(|&b| b != b'\n') {
                        at += 1;
                    }
                }
                _ => break,
            }
        }
        let start = at;
        let b = bytes[at];
        let token = if b.is_ascii_alphabetic() || b == b'_' {
            while bytes
                .get(at)
                .is_some_and(|b| b.is_ascii_alphanumeric() || *b == b'_')
            {
                at += 1;
            }
            Token::Ident(&text[start..at])
        } else if b.is_ascii_digit() {
            while bytes
                .get(at)
                .is_some_and(|b| b.is_ascii_digit() || matches!(b, b'.' | b'e' | b'E'))
                || (matches!(bytes.get(at), Some(b'+' | b'-'))
                    && matches!(bytes.get(at - 1), Some(b'e' | b'E')))
            {
                at += 1;
            }
            Token::Number(&text[start..at])
        } else if b == b'"' || b == b'\'' {
            at += 1;
            while bytes
                .get(at)
                .is_some_and(|&c| c != b && c != b'\n' && c != b'\\')
            {
                at += 1;
            }
            if bytes.get(at) != Some(&b) {
                return Some(Err(line));
            }
            at += 1;
            Token::Str
        } else if b == b'-' && bytes.get(at + 1) == Some(&b'>') {
            at += 2;
            Token::Arrow
        } else if b"()[]{},;=<>:-".contains(&b) {
            at += 1;
            Token::Punct(b)
        } else {
            return Some(Err(line));
        };
        Some(Ok((line, token)))
    })
}
