"""Figures. Only commands import this package; it imports matplotlib lazily, with the Agg backend."""
