//! Structs that carry their own size (`struct_size`, as `GrSettings`, `GrMesh` and `GrLight`):
//! how the C ABI grows without breaking. A library adds fields only at a struct's end and reads
//! a field only when the caller's `struct_size` covers it (else its default), so a host built
//! against an older header keeps working; a host built against a newer one is told so.

use super::error::Failure;

/// Checks a caller's `struct_size` (`given`) for the struct `what`: at least `first` (the size
/// of the struct's first sized version), at most `current` (this library's).
pub(crate) fn check(what: &str, given: u32, first: usize, current: usize, fill: &str) -> Result<(), Failure> {
    let given = given as usize;
    if given > current {
        return Err(Failure::invalid(format!(
            "{what}.struct_size is {given} but this library's struct has {current} bytes: the host \
             was built against a newer header than the library (check gr_abi_version)"
        )));
    }
    if given < first {
        return Err(Failure::invalid(format!(
            "{what}.struct_size is {given}, below the {first} bytes of its first version \
             (fill it with {fill})"
        )));
    }
    Ok(())
}
