//! Pickle values and opcodes in words, for messages: bounded however large or deep the value.
use super::Value;

/// Names of the opcodes outside the subset, for a useful refusal.
pub(super) fn opcode_name(op: u8) -> &'static str {
    match op {
        b'0' => "POP",
        b'1' => "POP_MARK",
        b'2' => "DUP",
        b'F' => "FLOAT",
        b'I' => "INT",
        b'L' => "LONG",
        b'P' => "PERSID",
        b'S' => "STRING",
        b'T' => "BINSTRING",
        b'U' => "SHORT_BINSTRING",
        b'V' => "UNICODE",
        b'g' => "GET",
        b'p' => "PUT",
        b'i' => "INST",
        b'o' => "OBJ",
        0x82 => "EXT1",
        0x83 => "EXT2",
        0x84 => "EXT4",
        0x8b => "LONG4",
        0x8e => "BINBYTES8",
        0x8f => "EMPTY_SET",
        0x90 => "ADDITEMS",
        0x91 => "FROZENSET",
        0x92 => "NEWOBJ_EX",
        0x96 => "BYTEARRAY8",
        0x97 => "NEXT_BUFFER",
        0x98 => "READONLY_BUFFER",
        _ => "not a pickle opcode",
    }
}

/// Characters of a value shown in a message.
const MAX_SHOWN: usize = 200;

/// `v` for a message, at most about [`MAX_SHOWN`] characters however large it is: a pickle can
/// hold a tuple of a million items, or one string fetched from the memo a thousand times.
pub fn brief(v: &Value) -> String {
    let mut out = String::new();
    describe(v, &mut out);
    if out.len() > MAX_SHOWN {
        let mut end = MAX_SHOWN;
        while !out.is_char_boundary(end) {
            end -= 1;
        }
        out.truncate(end);
        out.push_str("...");
    }
    out
}

fn describe(v: &Value, out: &mut String) {
    use std::fmt::Write;
    if out.len() > MAX_SHOWN {
        return;
    }
    match v {
        Value::Str(s) => {
            let cut: String = s.chars().take(MAX_SHOWN).collect();
            let _ = write!(out, "{cut:?}");
        }
        Value::Bytes(b) => {
            let _ = write!(out, "<{} bytes>", b.len());
        }
        Value::Tuple(items, _) => {
            out.push('(');
            for (i, item) in items.iter().enumerate() {
                if out.len() > MAX_SHOWN {
                    break;
                }
                if i > 0 {
                    out.push_str(", ");
                }
                describe(item, out);
            }
            out.push(')');
        }
        Value::Tensor(t) => {
            let _ = write!(
                out,
                "<tensor of storage {:?}>",
                t.storage.key.chars().take(64).collect::<String>()
            );
        }
        Value::Storage(s) => {
            let _ = write!(out, "<storage {:?}>", s.key.chars().take(64).collect::<String>());
        }
        other => {
            let _ = write!(out, "{other:?}");
        }
    }
}
