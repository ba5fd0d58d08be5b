"""Benchmarks against peer tools."""
