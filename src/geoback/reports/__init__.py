"""Reports: every file a command writes (tables, JSON, markdown, VTU) and every figure; readers only,
they never run the model."""
