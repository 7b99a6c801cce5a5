"""The model contract: the channel layout and encoding (encoding), the stride padding (padding), a frame's
conditioning (conditioning), how weights are stored (weights), and the ONNX model run (runtime, lean)."""
