"""Sample generation (Owen-scrambled Sobol) and the warps from uniform numbers to shapes, with pdfs."""
