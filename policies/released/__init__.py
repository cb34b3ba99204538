"""The released navigation models (GNM, ViNT, NoMaD, LogoNav of the MBRA release, CityWalker) in plain torch, their
weights read without running the files."""
