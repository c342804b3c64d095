"""The film: reconstruction filters, sample waves, tiles, and OpenEXR output."""
