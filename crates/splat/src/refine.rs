//! Successive refinement (Westover §4.2): a ladder of cheaper previews.
