"""Design of experiments: the seed's Taguchi studies (L16, L27), noise/CRLB and identifiability studies."""
