//! The thin-shell contraction simulator (SPEC section 1).
