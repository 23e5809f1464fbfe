# Reference solutions for the exercise notebooks (imported by the tests).
