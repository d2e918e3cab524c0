//! A strict reader of the small part of Python's pickle format that `torch.save` uses for a state
//! dict (protocol 2, plus the few protocol 3-4 opcodes that newer writers emit). Nothing is ever
//! executed: globals are kept as names, and only the handful of constructors a checkpoint needs
//! (`collections.OrderedDict`, `torch._utils._rebuild_tensor_v2`, `_rebuild_parameter`,
//! `torch._tensor._rebuild_from_type_v2`) are understood. Instances of any other class (e.g. the
//! `argparse.Namespace` of a training checkpoint) become opaque [`Value::Object`]s, so a full
//! checkpoint still parses and only its tensors are used. Any opcode outside the subset is refused
//! with its name and byte offset.
use std::collections::HashMap;
use std::rc::Rc;

mod describe;
pub use describe::brief;
use describe::opcode_name;

/// What one pickle may build, so that a hostile one cannot exhaust memory or the stack. A
/// state dict's pickle is small (a few values per tensor); these are far above any.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Bytes of values built (each value on the stack, in a container or the memo, plus the
    /// text and bytes it owns). Values fetched from the memo are shared, not copied, but each
    /// fetch still costs a value.
    pub built_bytes: usize,
    /// Nesting of tuples: dropping, comparing and printing a value recurse into it, so a
    /// million nested tuples would overflow the thread's stack.
    pub depth: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            built_bytes: 256 << 20,
            depth: 64,
        }
    }
}

/// Most dimensions of a tensor (torch's own limit is 64).
const MAX_DIMS: usize = 64;

/// Longest module or class name of a GLOBAL: Python names are short, and each instance of a
/// class copies its name.
const MAX_GLOBAL_NAME: usize = 1024;

/// The element type of a torch storage, from its class name (`torch.FloatStorage`, ...).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Dtype {
    F32,
    F16,
    Bf16,
    F64,
    /// A type this crate does not decode (integers, booleans, complex): its class name and
    /// element size, so that its storage can still be checked.
    Other(String, usize),
}

impl Dtype {
    fn from_storage_class(name: &str) -> Option<Dtype> {
        Some(match name {
            "FloatStorage" => Dtype::F32,
            "HalfStorage" => Dtype::F16,
            "BFloat16Storage" => Dtype::Bf16,
            "DoubleStorage" => Dtype::F64,
            _ => {
                let size = match name {
                    "LongStorage" | "ComplexFloatStorage" => 8,
                    "IntStorage" => 4,
                    "ShortStorage" => 2,
                    "CharStorage" | "ByteStorage" | "BoolStorage" => 1,
                    "ComplexDoubleStorage" => 16,
                    _ => return None,
                };
                Dtype::Other(name.to_string(), size)
            }
        })
    }

    pub fn size(&self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F16 | Dtype::Bf16 => 2,
            Dtype::F64 => 8,
            Dtype::Other(_, s) => *s,
        }
    }

    pub fn name(&self) -> &str {
        match self {
            Dtype::F32 => "float32",
            Dtype::F16 => "float16",
            Dtype::Bf16 => "bfloat16",
            Dtype::F64 => "float64",
            Dtype::Other(n, _) => n,
        }
    }
}

/// A storage named by a persistent id: its bytes are the archive entry `data/<key>`.
#[derive(Clone, Debug, PartialEq)]
pub struct StorageRef {
    pub dtype: Dtype,
    pub key: String,
    /// Elements (not bytes).
    pub numel: u64,
}

/// A tensor as `_rebuild_tensor_v2` describes it: a view into a storage.
#[derive(Clone, Debug, PartialEq)]
pub struct TensorRef {
    pub storage: Rc<StorageRef>,
    /// In elements.
    pub offset: u64,
    pub shape: Vec<usize>,
    pub stride: Vec<usize>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    /// Shared, so that a memo fetch does not copy the text.
    Str(Rc<str>),
    Bytes(Rc<[u8]>),
    /// The items and the nesting depth (1 for a tuple of no tuples).
    Tuple(Rc<Vec<Value>>, u32),
    /// Index into [`Pickle::dicts`]: dicts are shared and filled after being memoised, so they
    /// live in an arena and values refer to them.
    Dict(usize),
    /// Index into [`Pickle::lists`], for the same reason.
    List(usize),
    Global(Rc<(String, String)>),
    Storage(Rc<StorageRef>),
    Tensor(Rc<TensorRef>),
    /// An instance of a class that is not modelled, by its `module.name`.
    Object(String),
}

/// A parsed pickle: the root value and the containers it refers to.
#[derive(Debug, Default)]
pub struct Pickle {
    pub root: Option<Value>,
    pub dicts: Vec<Vec<(Value, Value)>>,
    pub lists: Vec<Vec<Value>>,
}

impl Pickle {
    /// The entry of dict `dict` whose key is the string `key`.
    pub fn get(&self, dict: usize, key: &str) -> Option<&Value> {
        self.dicts[dict]
            .iter()
            .find(|(k, _)| matches!(k, Value::Str(s) if &**s == key))
            .map(|(_, v)| v)
    }
}

/// Why a pickle was refused: a problem at a byte offset.
#[derive(Debug, PartialEq)]
pub struct PickleError {
    pub offset: usize,
    pub problem: String,
}

impl std::fmt::Display for PickleError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "byte {}: {}", self.offset, self.problem)
    }
}

/// A dict key that can be hashed: what a dict's keys are looked up by, so that a dict of many
/// keys is built in linear time. Other keys (tuples, objects) are kept without a lookup.
#[derive(Hash, PartialEq, Eq)]
enum Key {
    None,
    Bool(bool),
    Int(i64),
    Float(u64),
    Str(Rc<str>),
    Bytes(Rc<[u8]>),
}

impl Key {
    fn of(v: &Value) -> Option<Key> {
        Some(match v {
            Value::None => Key::None,
            Value::Bool(b) => Key::Bool(*b),
            Value::Int(i) => Key::Int(*i),
            Value::Float(f) => Key::Float(f.to_bits()),
            Value::Str(s) => Key::Str(s.clone()),
            Value::Bytes(b) => Key::Bytes(b.clone()),
            _ => return None,
        })
    }
}

struct Machine<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Offset of the opcode being run, for errors.
    at: usize,
    stack: Vec<Value>,
    marks: Vec<usize>,
    memo: HashMap<u32, Value>,
    /// Where each hashable key of each dict is: (dict, key) -> index in the dict.
    keys: HashMap<(usize, Key), usize>,
    limits: Limits,
    /// Bytes of values built so far (see [`Limits::built_bytes`]).
    built: usize,
    out: Pickle,
}

/// Parses `bytes` (a whole pickle) into values without running anything, within `limits`.
pub fn parse_with(bytes: &[u8], limits: Limits) -> Result<Pickle, PickleError> {
    let mut m = Machine {
        bytes,
        pos: 0,
        at: 0,
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
        keys: HashMap::new(),
        limits,
        built: 0,
        out: Pickle::default(),
    };
    m.run()?;
    Ok(m.out)
}

impl Machine<'_> {
    fn fail<T>(&self, problem: impl Into<String>) -> Result<T, PickleError> {
        Err(PickleError {
            offset: self.at,
            problem: problem.into(),
        })
    }

    fn take(&mut self, n: usize) -> Result<&[u8], PickleError> {
        if self.bytes.len() - self.pos < n {
            return self.fail(format!(
                "truncated: needs {n} more bytes, {} left",
                self.bytes.len() - self.pos
            ));
        }
        self.pos += n;
        Ok(&self.bytes[self.pos - n..self.pos])
    }

    fn u8(&mut self) -> Result<u8, PickleError> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, PickleError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }

    fn line(&mut self) -> Result<String, PickleError> {
        let rest = &self.bytes[self.pos..];
        let Some(n) = rest.iter().take(MAX_GLOBAL_NAME + 1).position(|&b| b == b'\n') else {
            return self.fail(if rest.len() > MAX_GLOBAL_NAME {
                format!("a GLOBAL name longer than {MAX_GLOBAL_NAME} bytes")
            } else {
                "truncated: a GLOBAL name without its newline".into()
            });
        };
        let s = String::from_utf8(rest[..n].to_vec());
        self.pos += n + 1;
        s.or_else(|_| self.fail("a GLOBAL name that is not UTF-8"))
    }

    fn utf8(&mut self, n: usize) -> Result<Value, PickleError> {
        let b = self.take(n)?;
        match std::str::from_utf8(b) {
            Ok(s) => {
                let s: Rc<str> = Rc::from(s);
                self.spend(s.len())?;
                Ok(Value::Str(s))
            }
            Err(_) => self.fail("a string that is not UTF-8"),
        }
    }

    /// Counts `bytes` more of values built against [`Limits::built_bytes`].
    fn spend(&mut self, bytes: usize) -> Result<(), PickleError> {
        self.built = self.built.saturating_add(bytes);
        if self.built > self.limits.built_bytes {
            return self.fail(format!(
                "builds more than {} bytes of values (a memo or container bomb?); a state dict's pickle \
                 builds far less",
                self.limits.built_bytes
            ));
        }
        Ok(())
    }

    /// Pushes a value, counting it.
    fn push(&mut self, v: Value) -> Result<(), PickleError> {
        self.spend(std::mem::size_of::<Value>())?;
        self.stack.push(v);
        Ok(())
    }

    /// A tuple of `items`, refused when it nests deeper than [`Limits::depth`].
    fn tuple_of(&self, items: Vec<Value>) -> Result<Value, PickleError> {
        let inner = items
            .iter()
            .map(|v| match v {
                Value::Tuple(_, d) => *d,
                _ => 0,
            })
            .max()
            .unwrap_or(0);
        let depth = inner + 1;
        if depth as usize > self.limits.depth {
            return self.fail(format!(
                "tuples nested more than {} deep; a state dict's are a few deep",
                self.limits.depth
            ));
        }
        Ok(Value::Tuple(Rc::new(items), depth))
    }

    fn pop(&mut self) -> Result<Value, PickleError> {
        match self.stack.pop() {
            Some(v) if self.marks.last().is_none_or(|&m| self.stack.len() >= m) => Ok(v),
            _ => self.fail("stack underflow (malformed pickle)"),
        }
    }

    /// The values pushed since the last MARK, which is removed.
    fn pop_mark(&mut self) -> Result<Vec<Value>, PickleError> {
        let Some(m) = self.marks.pop() else {
            return self.fail("no MARK to pop to (malformed pickle)");
        };
        Ok(self.stack.split_off(m))
    }

    fn top(&mut self) -> Result<&Value, PickleError> {
        match self.stack.last() {
            Some(v) => Ok(v),
            None => self.fail("empty stack (malformed pickle)"),
        }
    }

    fn tuple(&mut self, n: usize) -> Result<(), PickleError> {
        let mut items = Vec::with_capacity(n);
        for _ in 0..n {
            items.push(self.pop()?);
        }
        items.reverse();
        let t = self.tuple_of(items)?;
        self.stack.push(t);
        Ok(())
    }

    fn set_items(&mut self, items: Vec<Value>) -> Result<(), PickleError> {
        if !items.len().is_multiple_of(2) {
            return self.fail("SETITEMS with an odd number of values");
        }
        let Value::Dict(d) = *self.top()? else {
            return self.fail("SETITEM(S) on something that is not a dict");
        };
        let mut it = items.into_iter();
        while let (Some(k), Some(v)) = (it.next(), it.next()) {
            let entries = &mut self.out.dicts[d];
            match Key::of(&k) {
                Some(key) => match self.keys.entry((d, key)) {
                    std::collections::hash_map::Entry::Occupied(slot) => entries[*slot.get()].1 = v,
                    std::collections::hash_map::Entry::Vacant(slot) => {
                        slot.insert(entries.len());
                        entries.push((k, v));
                    }
                },
                // Unhashable in Python too (or an object): kept as it comes.
                None => entries.push((k, v)),
            }
        }
        Ok(())
    }

    fn append(&mut self, items: Vec<Value>) -> Result<(), PickleError> {
        let Value::List(l) = *self.top()? else {
            return self.fail("APPEND(S) on something that is not a list");
        };
        self.out.lists[l].extend(items);
        Ok(())
    }

    fn memo_put(&mut self, key: u32) -> Result<(), PickleError> {
        let v = self.top()?.clone();
        self.spend(2 * std::mem::size_of::<Value>())?;
        self.memo.insert(key, v);
        Ok(())
    }

    fn memo_get(&mut self, key: u32) -> Result<(), PickleError> {
        match self.memo.get(&key) {
            Some(v) => {
                let v = v.clone();
                self.push(v)
            }
            None => self.fail(format!("memo key {key} used before it was set")),
        }
    }

    fn run(&mut self) -> Result<(), PickleError> {
        loop {
            self.at = self.pos;
            let op = self.u8()?;
            match op {
                0x80 => {
                    let proto = self.u8()?;
                    if proto > 5 {
                        return self.fail(format!("pickle protocol {proto} (at most 5 is known)"));
                    }
                }
                // FRAME (protocol 4): only a length hint for buffered readers.
                0x95 => {
                    self.take(8)?;
                }
                b'.' => {
                    let root = self.pop()?;
                    if !self.stack.is_empty() || !self.marks.is_empty() {
                        return self.fail("STOP with values left on the stack");
                    }
                    self.out.root = Some(root);
                    return Ok(());
                }
                b'c' => {
                    let module = self.line()?;
                    let name = self.line()?;
                    self.spend(name.len() + module.len())?;
                    self.push(Value::Global(Rc::new((module, name))))?;
                }
                // STACK_GLOBAL (protocol 4): module and name from the stack.
                0x93 => {
                    let (Value::Str(name), Value::Str(module)) = (self.pop()?, self.pop()?) else {
                        return self.fail("STACK_GLOBAL without two strings");
                    };
                    if name.len().max(module.len()) > MAX_GLOBAL_NAME {
                        return self.fail(format!("a STACK_GLOBAL name longer than {MAX_GLOBAL_NAME} bytes"));
                    }
                    self.spend(name.len() + module.len())?;
                    self.push(Value::Global(Rc::new((module.to_string(), name.to_string()))))?;
                }
                // BINPUT, LONG_BINPUT, and MEMOIZE (protocol 4: the next free key).
                b'q' | b'r' | 0x94 => {
                    let k = match op {
                        b'q' => self.u8()? as u32,
                        b'r' => self.u32()?,
                        _ => self.memo.len() as u32,
                    };
                    self.memo_put(k)?;
                }
                // BINGET, LONG_BINGET.
                b'h' | b'j' => {
                    let k = if op == b'h' { self.u8()? as u32 } else { self.u32()? };
                    self.memo_get(k)?;
                }
                b'}' => {
                    self.spend(std::mem::size_of::<Vec<(Value, Value)>>())?;
                    self.out.dicts.push(Vec::new());
                    self.push(Value::Dict(self.out.dicts.len() - 1))?;
                }
                b']' => {
                    self.spend(std::mem::size_of::<Vec<Value>>())?;
                    self.out.lists.push(Vec::new());
                    self.push(Value::List(self.out.lists.len() - 1))?;
                }
                b'(' => self.marks.push(self.stack.len()),
                b's' => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    self.set_items(vec![k, v])?;
                }
                b'u' => {
                    let items = self.pop_mark()?;
                    self.set_items(items)?;
                }
                b'a' => {
                    let v = self.pop()?;
                    self.append(vec![v])?;
                }
                b'e' => {
                    let items = self.pop_mark()?;
                    self.append(items)?;
                }
                b't' => {
                    let items = self.pop_mark()?;
                    let t = self.tuple_of(items)?;
                    self.stack.push(t);
                }
                b')' => self.tuple(0)?,
                0x85 => self.tuple(1)?,
                0x86 => self.tuple(2)?,
                0x87 => self.tuple(3)?,
                b'J' => {
                    let v = i32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes"));
                    self.push(Value::Int(v as i64))?;
                }
                b'K' => {
                    let v = self.u8()?;
                    self.push(Value::Int(v as i64))?;
                }
                b'M' => {
                    let v = u16::from_le_bytes(self.take(2)?.try_into().expect("2 bytes"));
                    self.push(Value::Int(v as i64))?;
                }
                0x8a => {
                    let n = self.u8()? as usize;
                    if n > 8 {
                        return self.fail(format!("LONG1 of {n} bytes (more than 64 bits)"));
                    }
                    let b = self.take(n)?;
                    // Little-endian two's complement, sign-extended from its top byte.
                    let fill = if b.last().is_some_and(|&t| t & 0x80 != 0) {
                        0xff
                    } else {
                        0
                    };
                    let mut le = [fill; 8];
                    le[..n].copy_from_slice(b);
                    self.push(Value::Int(i64::from_le_bytes(le)))?;
                }
                b'G' => {
                    let v = f64::from_be_bytes(self.take(8)?.try_into().expect("8 bytes"));
                    self.push(Value::Float(v))?;
                }
                b'X' => {
                    let n = self.u32()? as usize;
                    let s = self.utf8(n)?;
                    self.push(s)?;
                }
                0x8c => {
                    let n = self.u8()? as usize;
                    let s = self.utf8(n)?;
                    self.push(s)?;
                }
                0x8d => {
                    let n = u64::from_le_bytes(self.take(8)?.try_into().expect("8 bytes"));
                    let s = self.utf8(usize::try_from(n).unwrap_or(usize::MAX))?;
                    self.push(s)?;
                }
                b'C' | b'B' => {
                    let n = if op == b'C' {
                        self.u8()? as usize
                    } else {
                        self.u32()? as usize
                    };
                    let b: Rc<[u8]> = Rc::from(self.take(n)?);
                    self.spend(b.len())?;
                    self.push(Value::Bytes(b))?;
                }
                b'N' => self.push(Value::None)?,
                0x88 => self.push(Value::Bool(true))?,
                0x89 => self.push(Value::Bool(false))?,
                b'Q' => {
                    let pid = self.pop()?;
                    let storage = self.persistent_load(&pid)?;
                    self.push(Value::Storage(Rc::new(storage)))?;
                }
                b'R' => {
                    let args = self.pop()?;
                    let callable = self.pop()?;
                    let v = self.reduce(&callable, &args)?;
                    self.push(v)?;
                }
                // NEWOBJ: `cls.__new__(cls, *args)` of a class we do not model.
                0x81 => {
                    let _args = self.pop()?;
                    let Value::Global(g) = self.pop()? else {
                        return self.fail("NEWOBJ of something that is not a class");
                    };
                    let object = format!("{}.{}", g.0, g.1);
                    self.spend(object.len())?;
                    self.push(Value::Object(object))?;
                }
                // BUILD sets an object's attributes (e.g. a state dict's `_metadata`), which no
                // caller needs: the state is dropped and the object kept.
                b'b' => {
                    let _state = self.pop()?;
                    self.top()?;
                }
                _ => {
                    return self.fail(format!(
                        "unsupported pickle opcode 0x{op:02x} ({}); this reader only knows the subset \
                         that torch.save writes for a state dict",
                        opcode_name(op)
                    ));
                }
            }
        }
    }

    /// torch's persistent id of a storage: `('storage', torch.FloatStorage, key, location, numel)`.
    fn persistent_load(&self, pid: &Value) -> Result<StorageRef, PickleError> {
        if let Value::Tuple(t, _) = pid
            && let [
                Value::Str(kind),
                Value::Global(class),
                Value::Str(key),
                Value::Str(_location),
                Value::Int(numel),
            ] = &t[..]
            && &**kind == "storage"
            && *numel >= 0
        {
            let Some(dtype) = Dtype::from_storage_class(&class.1).filter(|_| class.0 == "torch") else {
                return self.fail(format!("unknown storage type {}.{}", class.0, class.1));
            };
            return Ok(StorageRef {
                dtype,
                key: key.to_string(),
                numel: *numel as u64,
            });
        }
        self.fail(format!(
            "a persistent id that is not torch's ('storage', type, key, location, numel): {}",
            brief(pid)
        ))
    }

    fn reduce(&mut self, callable: &Value, args: &Value) -> Result<Value, PickleError> {
        let Value::Global(g) = callable else {
            return self.fail(format!("REDUCE of {}, which is not a global", brief(callable)));
        };
        let Value::Tuple(args, _) = args else {
            return self.fail(format!("REDUCE of {}.{} with arguments that are not a tuple", g.0, g.1));
        };
        match (g.0.as_str(), g.1.as_str()) {
            ("collections", "OrderedDict") if args.is_empty() => {
                self.out.dicts.push(Vec::new());
                Ok(Value::Dict(self.out.dicts.len() - 1))
            }
            // (storage, storage_offset, size, stride, requires_grad, backward_hooks[, metadata])
            ("torch._utils", "_rebuild_tensor_v2" | "_rebuild_tensor") => self.rebuild_tensor(args),
            // (tensor, requires_grad, backward_hooks[, state])
            ("torch._utils", "_rebuild_parameter" | "_rebuild_parameter_with_state") => match args.first() {
                Some(t @ Value::Tensor(_)) => Ok(t.clone()),
                _ => self.fail(format!("{} without a tensor", g.1)),
            },
            // (func, type, args, state): a tensor subclass; the tensor is `func(*args)`.
            ("torch._tensor", "_rebuild_from_type_v2") => match &args[..] {
                [func, _, inner, _] => self.reduce(func, inner),
                _ => self.fail("_rebuild_from_type_v2 with other than 4 arguments"),
            },
            (module, name) => {
                let object = format!("{module}.{name}");
                self.spend(object.len())?;
                Ok(Value::Object(object))
            }
        }
    }

    fn rebuild_tensor(&self, args: &[Value]) -> Result<Value, PickleError> {
        let dims = |v: &Value| -> Option<Vec<usize>> {
            let Value::Tuple(t, _) = v else { return None };
            t.iter()
                .map(|d| match d {
                    Value::Int(i) => usize::try_from(*i).ok(),
                    _ => None,
                })
                .collect()
        };
        match args {
            [Value::Storage(s), Value::Int(offset), size, stride, ..] if *offset >= 0 => {
                match (dims(size), dims(stride)) {
                    (Some(shape), Some(stride)) if shape.len() == stride.len() && shape.len() <= MAX_DIMS => {
                        Ok(Value::Tensor(Rc::new(TensorRef {
                            storage: s.clone(),
                            offset: *offset as u64,
                            shape,
                            stride,
                        })))
                    }
                    (Some(shape), _) if shape.len() > MAX_DIMS => {
                        self.fail(format!("a tensor of {} dimensions (at most {MAX_DIMS})", shape.len()))
                    }
                    _ => self.fail(format!(
                        "a tensor with size {} and stride {}",
                        brief(size),
                        brief(stride)
                    )),
                }
            }
            _ => self.fail("_rebuild_tensor_v2 without (storage, offset, size, stride, ...)"),
        }
    }
}
