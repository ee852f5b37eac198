"""embree_rt in the browser."""
