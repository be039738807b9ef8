"""What users run: the command line, the recover pipeline and its result files, rendering, relighting, the demo."""
