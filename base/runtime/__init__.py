"""Process helpers: real-time scheduling requests and starting the repository's own modules as children."""
