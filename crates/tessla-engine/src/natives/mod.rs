//! The registry of native (Rust) functions a spec reaches with `extern("name")`.
//!
//! Owns: the name -> implementation table. Types are not here: each native is declared with its
//! TeSSLa signature in a prelude or library spec (`def f(a: Int): Int = extern("f")`), and the
//! checker types calls from that declaration. Natives are strict: the evaluator passes no
//! `Value::Error` argument to a native (it propagates the first error itself), so an
//! implementation only handles well-typed, error-free values. Natives that take functions call
//! them through [`crate::value::Callable`].

pub mod core;
pub mod lidar;

use crate::value::Value;

/// A native implementation: well-typed, error-free arguments in, a value (maybe an error) out.
pub type NativeFn = fn(&[Value]) -> Value;

/// One entry of the registry.
#[derive(Debug, Clone, Copy)]
pub struct Native {
    pub name: &'static str,
    pub func: NativeFn,
}

/// The native named `name`, if any.
pub fn lookup(name: &str) -> Option<&'static Native> {
    REGISTRY.iter().find(|n| n.name == name)
}

/// Every native, for diagnostics that list the known names.
pub fn all() -> &'static [Native] {
    REGISTRY
}

static REGISTRY: &[Native] = &[
    Native {
        name: "intToFloat",
        func: core::int_to_float,
    },
    Native {
        name: "floatToInt",
        func: core::float_to_int,
    },
    Native {
        name: "pow",
        func: core::pow,
    },
    Native {
        name: "log",
        func: core::log,
    },
    Native {
        name: "sin",
        func: core::sin,
    },
    Native {
        name: "cos",
        func: core::cos,
    },
    Native {
        name: "tan",
        func: core::tan,
    },
    Native {
        name: "atan",
        func: core::atan,
    },
    Native {
        name: "sqrt",
        func: core::sqrt,
    },
    Native {
        name: "abs",
        func: core::abs,
    },
    Native {
        name: "max",
        func: core::max,
    },
    Native {
        name: "min",
        func: core::min,
    },
    Native {
        name: "toString",
        func: core::to_string,
    },
    Native {
        name: "List_size",
        func: core::list_size,
    },
    Native {
        name: "List_get",
        func: core::list_get,
    },
    Native {
        name: "List_fold",
        func: core::list_fold,
    },
    Native {
        name: "lidar_dropouts",
        func: lidar::dropouts,
    },
    Native {
        name: "lidar_spikes",
        func: lidar::spikes,
    },
    Native {
        name: "lidar_sector_min",
        func: lidar::sector_min,
    },
    Native {
        name: "lidar_sector_valid_fraction",
        func: lidar::sector_valid_fraction,
    },
];
