"""Command line of activebonds."""
