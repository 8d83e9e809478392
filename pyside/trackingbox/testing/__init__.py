"""Helpers for testing trackingbox and programs built on it (not used by the stages)."""
