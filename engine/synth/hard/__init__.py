"""The difficulties of real scans for generated buildings: hard plans, elements, furniture and scan defects."""
