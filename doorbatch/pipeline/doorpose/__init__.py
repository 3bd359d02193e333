"""Door poses from camera detections fused with a laser line fit, goal poses, positioning (paper 003)."""
