"""Per-frame trackers with a streaming ``update(sample) -> pose`` interface."""
