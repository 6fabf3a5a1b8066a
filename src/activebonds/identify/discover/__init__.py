"""Model discovery: a candidate model written from a recording, the bonds it needs, the masses a flight determines."""
