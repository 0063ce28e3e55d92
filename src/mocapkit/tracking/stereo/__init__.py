"""Stereo / multi-view markerless upper-body tracker of Azad, Asfour & Dillmann 2008."""
