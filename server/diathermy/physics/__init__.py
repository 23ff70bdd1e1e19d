"""The model's physics as pure functions over numpy arrays (SI units throughout)."""
