"""greybench: the command-line interface composing identify, simulate and service."""
