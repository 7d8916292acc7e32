//! `wire_enum!`: a `u8`-backed enum of the interface with its raw values and names declared once.

/// Declares a `#[repr(u8)]` enum whose raw values and names are listed once: `ALL`, `raw`,
/// `from_raw` (unknown bytes are `None`), `name`, `Display`, `FromStr` and serde by name all
/// come from the one list, so a new variant cannot be forgotten in a decoder.
macro_rules! wire_enum {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident = $value:literal => $text:literal,)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
        #[repr(u8)]
        pub enum $name {
            $($(#[$vmeta])* #[serde(rename = $text)] $variant = $value,)+
        }

        impl $name {
            /// Every value, in declaration order.
            pub const ALL: &'static [$name] = &[$(Self::$variant,)+];

            /// The byte on the wire.
            pub const fn raw(self) -> u8 {
                self as u8
            }

            /// The value of a byte, or `None` for a byte this version does not know.
            pub const fn from_raw(raw: u8) -> Option<Self> {
                match raw {
                    $($value => Some(Self::$variant),)+
                    _ => None,
                }
            }

            /// The name in JSON, logs and on the command line.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $text,)+
                }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $name {
            type Err = $crate::control::UnknownName;

            fn from_str(text: &str) -> Result<Self, Self::Err> {
                Self::ALL
                    .iter()
                    .copied()
                    .find(|value| value.name() == text)
                    .ok_or_else(|| $crate::control::UnknownName {
                        what: stringify!($name),
                        found: text.to_owned(),
                        expected: Self::ALL.iter().map(|value| value.name()).collect(),
                    })
            }
        }
    };
}
