//! Latest value and timestamp per named signal, with staleness detection.
