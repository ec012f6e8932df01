"""Build tooling (extension zip, bundled wheels). Excluded from the extension zip itself."""
