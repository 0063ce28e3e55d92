"""Monocular markerless tracking (Mamania, Shaji, Chandran 2004): flips, pruning, Viterbi."""
