"""The paper's experiments (Stanciulescu & Louchet 2000, §4), reproducible with one command each."""
