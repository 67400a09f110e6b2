"""Tracker routes: pivot, hand-eye, N-wire (+ PLUS variants), multi-wedge, arbitrary wire."""
