"""Benches: the upper-computer side of tests: a protocol client, scenarios, conformance."""
