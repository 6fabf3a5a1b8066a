"""Gap filling with a fitted model: its trajectory fitted to the markers around each gap."""
