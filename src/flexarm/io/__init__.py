"""Every file in and out: log readers (text, MATLAB), log-format files, the one atomic writer."""
