//! Contact mechanics (being written).
