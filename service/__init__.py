"""Marionette pose service (onnxruntime + numpy; never torch)."""
