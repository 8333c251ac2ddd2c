//! XML documents from untrusted text (URDF, COLLADA): roxmltree's parse, after a linear scan that refuses
//! an element with more attributes than any real file has (roxmltree checks each attribute against the
//! element's others, so its time grows with the square of their number: 150,000 attributes took 15 s).

use roxmltree::Document;

/// The most attributes one element may have.
pub const MAX_ATTRIBUTES: usize = 1024;

/// The document `text` holds, or what is wrong with it.
pub fn parse(text: &str) -> Result<Document<'_>, String> {
    if let Some(line) = crowded_element(text) {
        return Err(format!("not valid XML: an element at line {line} has more than {MAX_ATTRIBUTES} attributes"));
    }
    crate::validate::check_cancelled("xml").map_err(|e| e.to_string())?;
    Document::parse(text).map_err(|e| format!("not valid XML: {e}"))
}

/// The line of the first start tag with more than `MAX_ATTRIBUTES` attributes (counted as the `=` signs
/// outside quotes), skipping comments, CDATA sections, processing instructions and declarations. Malformed
/// text is left to the parser.
fn crowded_element(text: &str) -> Option<usize> {
    let bytes = text.as_bytes();
    let mut at = 0;
    let mut tags = 0usize;
    while let Some(offset) = bytes[at..].iter().position(|&b| b == b'<') {
        tags += 1;
        if tags.is_multiple_of(crate::validate::CANCEL_INTERVAL) && crate::validate::check_cancelled("xml").is_err() {
            // A cancelled load: the parse that follows is not wanted either (see `parse`).
            return None;
        }
        let start = at + offset;
        let rest = &text[start..];
        let skip_to = |end: &str| rest.find(end).map_or(bytes.len(), |i| start + i + end.len());
        if rest.starts_with("<!--") {
            at = skip_to("-->");
        } else if rest.starts_with("<![CDATA[") {
            at = skip_to("]]>");
        } else if rest.starts_with("<?") {
            at = skip_to("?>");
        } else {
            let (mut quote, mut attributes, mut end) = (None, 0, bytes.len());
            for (i, &b) in bytes.iter().enumerate().skip(start + 1) {
                match (quote, b) {
                    (Some(q), _) if b == q => quote = None,
                    (Some(_), _) => {}
                    (None, b'"' | b'\'') => quote = Some(b),
                    (None, b'=') => attributes += 1,
                    (None, b'>') => {
                        end = i + 1;
                        break;
                    }
                    _ => {}
                }
            }
            if attributes > MAX_ATTRIBUTES {
                return Some(text[..start].matches('\n').count() + 1);
            }
            at = end;
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_element_with_too_many_attributes_is_refused_with_its_line() {
        let crowded: String = (0..=MAX_ATTRIBUTES).map(|i| format!(" a{i}='>'")).collect();
        let text = format!("<r>\n<!-- <x {crowded}/> -->\n<e{crowded}/></r>");
        let error = parse(&text).unwrap_err();
        assert!(error.contains("line 3") && error.contains("more than 1024 attributes"), "{error}");
        let fine: String = (0..MAX_ATTRIBUTES).map(|i| format!(" a{i}=\"=\"")).collect();
        assert!(parse(&format!("<r><e{fine}/></r>")).is_ok());
    }
}
