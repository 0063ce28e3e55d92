"""End-to-end jobs: run a tracker over a recording, calibrate, demo, benchmarks."""
