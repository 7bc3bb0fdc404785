"""Small FMUs the orchestrator tests run: built with the same pipeline as the product FMUs."""
