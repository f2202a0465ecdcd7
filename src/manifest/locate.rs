//! Where each value sits in the YAML source: a map from dotted field paths to line/column.
//!
//! Built by walking the event stream of `granit-parser` (the parser serde-saphyr uses, reached
//! through its re-export, so it is always the same version). Used to put a location on
//! validation errors, and to find the field path of a serde error from its location.

use std::collections::BTreeMap;

use serde_saphyr::granit_parser::{Event, Parser, Span};

/// A 1-based line and 1-based (character) column, ordered by position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Pos {
    pub line: usize,
    pub column: usize,
}

impl Pos {
    fn start(span: &Span) -> Pos {
        Pos {
            line: span.start.line(),
            column: span.start.col() + 1,
        }
    }
    fn end(span: &Span) -> Pos {
        Pos {
            line: span.end.line(),
            column: span.end.col() + 1,
        }
    }
}

/// One mapping entry of the source.
#[derive(Debug, Clone)]
pub struct Entry {
    /// Start and end of the key.
    pub key: (Pos, Pos),
    /// Start and end of the value node (for collections, up to their end event).
    pub value: (Pos, Pos),
    /// The value is an alias (`*name`) or the entry is a merge key (`<<`): the fields below
    /// it are not written out in place.
    pub indirect: bool,
    /// The text of a scalar value (after YAML unescaping).
    pub scalar: Option<String>,
}

/// Dotted path -> entry, for every mapping entry with a scalar key (sequence items get their
/// index as a path segment).
#[derive(Debug, Clone, Default)]
pub struct SourceMap {
    pub entries: BTreeMap<String, Entry>,
}

impl SourceMap {
    /// Walk `text`; best effort: on a syntax error, what was seen so far is kept.
    pub fn build(text: &str) -> SourceMap {
        let mut events = Parser::new_from_str(text)
            .map_while(|r| r.ok())
            .filter(|(ev, _)| is_node_event(ev));
        let mut map = SourceMap::default();
        // Skip to the first document's root node.
        for (ev, span) in events.by_ref() {
            if let Event::DocumentStart(..) = ev {
                if let Some((root, root_span)) = events.next() {
                    walk_node(&mut events, root, root_span, "", &mut map);
                }
                break;
            }
            let _ = span;
        }
        map
    }

    /// Location of the value at `path`, if it was written in the source.
    pub fn value_pos(&self, path: &str) -> Option<Pos> {
        self.entries.get(path).map(|e| e.value.0)
    }

    /// Location for a value at `path` that is written in the source, directly or through an
    /// alias or merge key of one of its ancestors (then the alias's location).
    pub fn written_pos(&self, path: &str) -> Option<Pos> {
        if let Some(p) = self.value_pos(path) {
            return Some(p);
        }
        let mut prefix = path;
        while let Some(i) = prefix.rfind('.') {
            prefix = &prefix[..i];
            if let Some(e) = self.entries.get(prefix) {
                return e.indirect.then_some(e.value.0);
            }
            if let Some(e) = self.entries.get(&format!("{prefix}.<<")) {
                return Some(e.value.0);
            }
        }
        None
    }

    /// The entry whose key starts at `pos`.
    pub fn key_at(&self, pos: Pos) -> Option<&str> {
        self.entries
            .iter()
            .find(|(_, e)| e.key.0 == pos)
            .map(|(p, _)| p.as_str())
    }

    /// The innermost entry whose value contains `pos` (start inclusive, end exclusive).
    pub fn value_containing(&self, pos: Pos) -> Option<&str> {
        let mut best: Option<(&str, (Pos, Pos))> = None;
        for (path, e) in &self.entries {
            let (start, end) = e.value;
            if start <= pos && (pos < end || (start == end && pos == start)) {
                let narrower = match best {
                    None => true,
                    Some((_, b)) => b.0 <= start && end <= b.1,
                };
                if narrower {
                    best = Some((path, e.value));
                }
            }
        }
        best.map(|(p, _)| p)
    }

    /// The entry at `pos`: the one whose key starts there, else the innermost value around it.
    pub fn path_at(&self, pos: Pos) -> Option<&str> {
        self.key_at(pos).or_else(|| self.value_containing(pos))
    }
}

fn is_node_event(ev: &Event<'_>) -> bool {
    matches!(
        ev,
        Event::DocumentStart(..)
            | Event::DocumentEnd
            | Event::Alias(_)
            | Event::UnresolvedAlias(_)
            | Event::Scalar(..)
            | Event::SequenceStart(..)
            | Event::SequenceEnd
            | Event::MappingStart(..)
            | Event::MappingEnd
    )
}

fn scalar_text(ev: &Event<'_>) -> Option<String> {
    match ev {
        Event::Scalar(s, ..) => Some(s.to_string()),
        _ => None,
    }
}

fn join(prefix: &str, seg: &str) -> String {
    if prefix.is_empty() {
        seg.to_string()
    } else {
        format!("{prefix}.{seg}")
    }
}

/// Consume the rest of the node that started with `ev`; record entries below `path`.
/// Returns the end position of the node.
fn walk_node<'a, I>(
    events: &mut I,
    ev: Event<'a>,
    span: Span,
    path: &str,
    map: &mut SourceMap,
) -> Pos
where
    I: Iterator<Item = (Event<'a>, Span)>,
{
    match ev {
        Event::MappingStart(..) => loop {
            let Some((kev, kspan)) = events.next() else {
                return Pos::end(&span);
            };
            if let Event::MappingEnd = kev {
                return Pos::end(&kspan);
            }
            let key_text = match &kev {
                Event::Scalar(s, ..) => Some(s.to_string()),
                _ => None,
            };
            let key_end = walk_node(events, kev, kspan, "", &mut SourceMap::default());
            let Some((vev, vspan)) = events.next() else {
                return key_end;
            };
            let indirect = matches!(vev, Event::Alias(_)) || key_text.as_deref() == Some("<<");
            let scalar = scalar_text(&vev);
            let child = key_text.as_deref().map(|k| join(path, k));
            let vstart = Pos::start(&vspan);
            let vend = match &child {
                Some(child) => walk_node(events, vev, vspan, child, map),
                None => walk_node(events, vev, vspan, "", &mut SourceMap::default()),
            };
            if let Some(child) = child {
                map.entries.insert(
                    child,
                    Entry {
                        key: (Pos::start(&kspan), key_end),
                        value: (vstart, vend),
                        indirect,
                        scalar,
                    },
                );
            }
        },
        Event::SequenceStart(..) => {
            let mut i = 0usize;
            loop {
                let Some((iev, ispan)) = events.next() else {
                    return Pos::end(&span);
                };
                if let Event::SequenceEnd = iev {
                    return Pos::end(&ispan);
                }
                let child = join(path, &i.to_string());
                let start = Pos::start(&ispan);
                let indirect = matches!(iev, Event::Alias(_));
                let scalar = scalar_text(&iev);
                let end = walk_node(events, iev, ispan, &child, map);
                map.entries.insert(
                    child,
                    Entry {
                        key: (start, start),
                        value: (start, end),
                        indirect,
                        scalar,
                    },
                );
                i += 1;
            }
        }
        _ => Pos::end(&span),
    }
}
