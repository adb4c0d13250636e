"""The lab's data generation and training; the product packages never import it."""
