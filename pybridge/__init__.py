"""pybridge package."""
