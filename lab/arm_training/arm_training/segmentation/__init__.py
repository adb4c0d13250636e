"""Data and training of the segmentation's boundary network and learned classifiers."""
