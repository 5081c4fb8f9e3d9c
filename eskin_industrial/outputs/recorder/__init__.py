"""The recorder output: every update to a CSV or JSONL file."""
