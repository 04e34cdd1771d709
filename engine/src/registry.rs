//! Registries of things of one's own, known by name (small-step kernels,
//! exchange moves): settings and checkpoints carry the name, and the
//! registry gives the thing back. Lock-free and `no_std`: a fixed table of
//! [`MOST`] slots, each set once.

use alloc::boxed::Box;

use once_cell::race::OnceBox;

/// How many things of one kind a process can register.
pub(crate) const MOST: usize = 32;

/// Why a registration was refused.
pub(crate) enum Refused {
    /// Another thing (or a built-in) has the name.
    NameTaken,
    /// [`MOST`] things are registered already.
    Full,
}

/// Named `&'static T`s, registered at most once each.
pub(crate) struct Registry<T: ?Sized + 'static> {
    slots: [OnceBox<&'static T>; MOST],
    /// The name of a registered thing.
    name: fn(&T) -> &'static str,
}

impl<T: ?Sized + 'static> Registry<T> {
    pub(crate) const fn new(name: fn(&T) -> &'static str) -> Self {
        Self {
            slots: [const { OnceBox::new() }; MOST],
            name,
        }
    }

    /// Registers `thing` under its name (again for the same thing: nothing
    /// changes), unless a built-in of `built_in` or another registered
    /// thing has that name, or the table is full.
    pub(crate) fn register(&self, thing: &'static T, built_in: &[&str]) -> Result<(), Refused> {
        let name = (self.name)(thing);
        if built_in.contains(&name) {
            return Err(Refused::NameTaken);
        }
        for slot in &self.slots {
            let held = *slot.get_or_init(|| Box::new(thing));
            if core::ptr::addr_eq(held, thing) {
                return Ok(());
            }
            if (self.name)(held) == name {
                return Err(Refused::NameTaken);
            }
        }
        Err(Refused::Full)
    }

    /// The registered thing called `name`.
    pub(crate) fn find(&self, name: &str) -> Option<&'static T> {
        self.slots
            .iter()
            .map_while(OnceBox::get)
            .copied()
            .find(|held| (self.name)(held) == name)
    }
}
