"""Scenarios, mission files, the search logic shared by training and flight, geodesy and SAR datasets."""
