"""Small helpers every layer uses: quoting text for messages, writing files whole, finding
plugins by entry point.  Imports the standard library only."""
