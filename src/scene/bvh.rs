//! Placeholder until the BVH lands (replaced in this change).
