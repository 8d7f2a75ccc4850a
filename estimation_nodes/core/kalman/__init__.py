"""The Kalman filter: scalar (the book's Algorithm 4), fusion of two estimates, matrix form."""
