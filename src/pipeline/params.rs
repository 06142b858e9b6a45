//! Declarative parameter blocks: one macro declares a table or stage kind's fields once and derives
//! from that single declaration the raw form a person writes (every field optional), the resolved form
//! generators take (every field present, defaults filled), preset merging, and the field reference used
//! by `schemas/`.
//!
//! Input: a field list with type, default, unit, valid range and doc text.
//! Output: `Raw` (deserialised from RON, `deny_unknown_fields`) and `Resolved` structs plus `FIELDS`.
//! Invariant: the raw and resolved forms can never disagree on field names, because both come from
//! the same token list.

/// Documentation of one field, rendered into `schemas/reference.md` and the JSON schema.
#[derive(Debug, Clone, Copy)]
pub struct FieldDoc {
    /// Field name as written in RON.
    pub name: &'static str,
    /// Rust type, as written in the declaration.
    pub ty: &'static str,
    /// Physical unit, or "" when dimensionless.
    pub unit: &'static str,
    /// Valid range, in words a person can act on.
    pub range: &'static str,
    /// What the field means.
    pub doc: &'static str,
}

/// Declares a parameter block. See the module doc.
///
/// ```text
/// declare_params! {
///     /// doc
///     raw RawName => resolved ResolvedName, kind "KindName" {
///         /// field doc
///         field: Type = default_expr, unit = "…", range = "…";
///     }
/// }
/// ```
#[macro_export]
macro_rules! declare_params {
    (
        $(#[doc = $sdoc:literal])*
        raw $raw:ident => resolved $resolved:ident, kind $kind:literal {
            $(
                $(#[doc = $fdoc:literal])*
                $field:ident : $ty:ty = $default:expr, unit = $unit:literal, range = $range:literal;
            )*
        }
    ) => {
        $(#[doc = $sdoc])*
        ///
        /// This is the form written in pipeline files: every field may be omitted (it then takes its
        /// preset's value, else its documented default).
        #[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
        #[serde(deny_unknown_fields)]
        pub struct $raw {
            /// Unique id of this entry within the pipeline (letters, digits, `_`, `-`, `.`).
            /// Required in `tables`/`stages`; not allowed in `presets`/`overrides`.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub id: Option<String>,
            /// Name of a preset (same kind) whose values this entry starts from.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub preset: Option<String>,
            $(
                $(#[doc = $fdoc])*
                #[serde(default, skip_serializing_if = "Option::is_none")]
                pub $field: Option<$ty>,
            )*
        }

        $(#[doc = $sdoc])*
        ///
        /// Resolved form: every field present. Its canonical RON is part of the content key.
        #[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
        pub struct $resolved {
            $(
                $(#[doc = $fdoc])*
                pub $field: $ty,
            )*
        }

        impl Default for $resolved {
            fn default() -> Self {
                Self { $( $field: $default, )* }
            }
        }

        impl $raw {
            /// Kind name as written in RON.
            pub const KIND: &'static str = $kind;
            /// What the kind does: its doc comment (the lines joined).
            pub const ABOUT: &'static str = concat!($($sdoc, "\n"),*);
            /// Field documentation, in declaration order.
            pub const FIELDS: &'static [$crate::pipeline::params::FieldDoc] = &[
                $( $crate::pipeline::params::FieldDoc {
                    name: stringify!($field),
                    ty: stringify!($ty),
                    unit: $unit,
                    range: $range,
                    doc: concat!($($fdoc, "\n"),*),
                }, )*
            ];

            /// `self` with every unset field taken from `base` (a preset, or the table an override
            /// applies to). Keeps `self`'s id; the preset link is `self`'s, else `base`'s.
            pub fn merged_over(&self, base: &Self) -> Self {
                Self {
                    id: self.id.clone().or_else(|| base.id.clone()),
                    preset: self.preset.clone().or_else(|| base.preset.clone()),
                    $( $field: self.$field.clone().or_else(|| base.$field.clone()), )*
                }
            }

            /// Fills unset fields with their documented defaults.
            pub fn resolve(&self) -> $resolved {
                let d = $resolved::default();
                $resolved { $( $field: self.$field.clone().unwrap_or(d.$field), )* }
            }

            /// Names of the fields set explicitly in this entry (for error locations).
            pub fn set_fields(&self) -> Vec<&'static str> {
                let mut v = Vec::new();
                $( if self.$field.is_some() { v.push(stringify!($field)); } )*
                v
            }
        }

        impl $resolved {
            /// Default value of every field as JSON, for the schema and the reference page.
            pub fn defaults_json() -> Vec<(&'static str, serde_json::Value)> {
                let d = Self::default();
                vec![ $( (stringify!($field), serde_json::to_value(&d.$field).unwrap_or(serde_json::Value::Null)), )* ]
            }
        }
    };
}
