"""Calibration of the acoustic twin's stack to measured data (placeholder replaced below)."""
