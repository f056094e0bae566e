//! Buchanan filtering (being written).
