//! `listed!`: an enum and its `ALL` from one list of variants, so that no variant can be left
//! out of `ALL` (the list every parser, help text and test walks).

/// Declares `enum NAME { ... }` as written (attributes, doc comments and discriminants kept) and
/// `NAME::ALL`, an array of every variant in declaration order.
#[macro_export]
macro_rules! listed {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident {
            $($(#[$vmeta:meta])* $variant:ident $(= $value:expr)?,)+
        }
    ) => {
        $(#[$meta])*
        $vis enum $name {
            $($(#[$vmeta])* $variant $(= $value)?,)+
        }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: [$name; [$(stringify!($variant)),+].len()] = [$($name::$variant,)+];
        }
    };
}
