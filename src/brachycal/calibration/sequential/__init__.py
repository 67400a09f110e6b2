"""The paper's sequential calibration: tool tips, rotations, image to probe, leave-one-out."""
