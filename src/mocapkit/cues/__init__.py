"""Image cues: edges and their distance transform, skin colour, blobs."""
