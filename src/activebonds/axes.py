"""The axes' letters, the one table of them: labels, vertical axes (``--up +Z``), parameter
names and file names read and write them (file names and labels may in lower case)."""

AXES = "XYZ"
