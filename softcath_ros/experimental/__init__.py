"""Comparison-only variants of the rungs: what studies in benchmarks/ need to measure a choice
the production rungs made (not registered as rungs, not listed by ``softcath models``)."""
