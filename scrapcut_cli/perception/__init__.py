"""Paint colour filter, back-projection, outlier removal, downsampling and stitching."""
