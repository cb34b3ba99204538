"""The released navigation models (GNM, ViNT, NoMaD), their weights read without running the files, in plain torch."""
