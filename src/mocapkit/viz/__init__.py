"""Drawing skeletons and cues over images for inspection."""
