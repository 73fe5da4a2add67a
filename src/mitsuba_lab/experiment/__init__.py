"""Strategy sweeps: config -> plan -> reference -> run -> store -> report."""
