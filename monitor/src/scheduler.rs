//! Steps each monitor at its own rate as time advances.
