"""Camera, marker and frame-ring models shared by the vision pipeline and the camera simulator."""
