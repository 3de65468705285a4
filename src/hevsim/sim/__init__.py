"""Forward-looking simulation: kernels, results and metrics."""
