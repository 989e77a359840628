"""Conventions and plumbing every stage shares: directions and layouts, cameras, HDR files, GL context."""
