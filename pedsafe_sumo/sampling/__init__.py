"""Sampling designs for the batch's episodes: plain Monte Carlo and importance sampling."""
