// PyO3 binding (next commit)
