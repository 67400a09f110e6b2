"""Readers of other tools' files: CSV joint logs, ROS bags, MetaImage, PLUS XML."""
