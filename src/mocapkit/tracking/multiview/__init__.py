"""Model-based multi-view tracking: a jointed full body fitted to every view's detections."""
