"""Spectral prediction: colour under named lights (``lights``) and band renders of a spectral ink table
(``render``). docs/spectral.md describes both."""
