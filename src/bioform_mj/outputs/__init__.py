"""What a run produces: files (atomic), video, rerun recording, figures — observers of a run or of its log."""
