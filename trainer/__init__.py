"""Marionette trainer: mocap -> canonical dataset -> models -> ONNX + manifest."""
