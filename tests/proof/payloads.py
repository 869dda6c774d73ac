"""The payloads the soft-proof tests plant in the page's fields (conftest.py, test_hostile.py, test_browser.py)."""

# Script planted in every user string that reaches the page: each payload tries another way out (an element in
# text, the end of a <script> element, the end of a quoted attribute, a comment, a line separator inside script
# data) and marks whatever it would make with a `pwn` attribute, which tests look for in the page and the DOM.
PAYLOADS = (
    "<img src=x pwn onerror=alert(1)>",
    "</script><script pwn>alert(2)</script>",
    "\"'><svg pwn onload=alert(3)>",
    "<!--<script pwn>alert(4)</script>-->",
    "\u2028</title></style><b pwn>5</b>",
    "<details pwn open ontoggle=alert(6)>",
    "'><math><style><img src=x pwn onerror=alert(7)>",
)
FILE_PAYLOADS = tuple(p for p in PAYLOADS if "/" not in p)  # file names cannot hold a slash
