"""*How* a certificate becomes numbers: the one conic standard form (:mod:`.conic`, image or kernel Gram
form) and compile-once structures filled per instance (:mod:`.compiled`)."""
