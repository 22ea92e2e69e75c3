"""Image poses from the images and the odometry (thesis Section 6.1)."""
