"""Running experiments: the batch runner and its executors, and what one work unit computes."""
