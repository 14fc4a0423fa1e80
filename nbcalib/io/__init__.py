"""Reading and writing files: ``calib.json``, camera files, point clouds, images, bags."""
