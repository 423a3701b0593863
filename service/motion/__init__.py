"""Motion: a schedule of a path-derived graph -> dependency plan -> executed trajectories."""
