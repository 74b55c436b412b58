//! What point-cloud and mesh PLY files share: a vertex read as named f64
//! scalars ([`Scalars`]), the header read with a message that names the
//! line at fault ([`read_header`]), and the scalar `x y z` every vertex
//! needs ([`check_xyz`]). `points::io` and `mesh::io` read through these.

use std::io::BufRead;
use std::marker::PhantomData;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Header, KeyMap, PropertyAccess, PropertyAccessResult, PropertyDef, PropertyType};

/// The property names a [`Scalars`] record keeps, in slot order (at most 16).
pub(crate) trait Names: Copy + Default + std::fmt::Debug {
    /// The names; any other property of the element is ignored.
    const NAMES: &'static [&'static str];
}

/// One PLY element as read: each of `N::NAMES` as f64 (0 when absent), and
/// which of them the file set.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Scalars<N: Names> {
    /// Slot `k` holds `N::NAMES[k]`.
    pub(crate) v: [f64; 16],
    /// Bit `k`: slot `k` was set.
    pub(crate) set: u32,
    names: PhantomData<N>,
}

impl<N: Names> Scalars<N> {
    /// A record of `values` in slot order (for writing).
    pub(crate) fn of(values: &[f64]) -> Scalars<N> {
        let mut v = [0.0; 16];
        v[..values.len()].copy_from_slice(values);
        Scalars {
            v,
            set: 0,
            names: PhantomData,
        }
    }

    fn put(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        match N::NAMES.iter().position(|n| *n == name) {
            Some(k) => {
                self.v[k] = value;
                self.set |= 1 << k;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }

    /// The value of `name`, if it is one of `N::NAMES`.
    pub(crate) fn get(&self, name: &str) -> Option<f64> {
        N::NAMES.iter().position(|n| *n == name).map(|k| self.v[k])
    }
}

impl<N: Names> PropertyAccess for Scalars<N> {
    fn new() -> Self {
        Scalars::default()
    }
    fn set_char(&mut self, name: &str, value: i8) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_uchar(&mut self, name: &str, value: u8) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_short(&mut self, name: &str, value: i16) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_ushort(&mut self, name: &str, value: u16) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_int(&mut self, name: &str, value: i32) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_uint(&mut self, name: &str, value: u32) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        self.put(name, value.into())
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.put(name, value)
    }
    fn get_double(&self, name: &str) -> Option<f64> {
        self.get(name)
    }
    fn get_float(&self, name: &str) -> Option<f32> {
        self.get(name).map(|v| v as f32)
    }
}

/// The file's header, or what is wrong with it naming the line: the line
/// the parser names, the whole header when its format line is missing or
/// has no version, or the line being read (invalid UTF-8, an empty file).
pub(crate) fn read_header<E: PropertyAccess, R: BufRead>(reader: &mut Reader<R>) -> Result<Header, String> {
    Parser::<E>::new().read_header(reader).map_err(|e| {
        let at = reader.line();
        match (e.line(), e.kind()) {
            (Some(_), _) => format!("PLY header: {e}"),
            (None, std::io::ErrorKind::InvalidInput) => {
                format!("PLY header, lines 1 to {}: {e}", at.saturating_sub(1).max(1))
            }
            (None, _) => format!("PLY header: Line {at}: {e}"),
        }
    })
}

/// `x`, `y` and `z` are scalar properties of the vertex element `props`.
pub(crate) fn check_xyz(props: &KeyMap<PropertyDef>) -> Result<(), String> {
    for name in ["x", "y", "z"] {
        match props.get(name).map(|p| &p.data_type) {
            None => return Err(format!("PLY vertex element has no `{name}` property")),
            Some(PropertyType::List(..)) => {
                return Err(format!("PLY vertex property `{name}` is a list, expected a scalar"))
            }
            Some(PropertyType::Scalar(_)) => {}
        }
    }
    Ok(())
}
