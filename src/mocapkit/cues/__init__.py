"""Image cues: edges and their distance transform, skin colour, blobs; the person followed
among 2-D detections."""
