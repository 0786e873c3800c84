"""The paper's transfer experiments as batch jobs: specs, runner, executors, results, figures."""
