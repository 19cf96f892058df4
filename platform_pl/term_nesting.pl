:- module(term_nesting,
          [ text_nesting_within/2,      % +Text, +MaxDepth
            term_depth_within/2         % @Term, +MaxDepth
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(lists), [append/3]).
:- use_module(library(error), [must_be/2]).

/** <module> How deep a text or a term nests, within a limit

A text frame from a peer (wire.pl) is parsed only if its brackets nest
at most MaxDepth deep, counted in one pass over its codes without
parsing it (text_nesting_within/2); a term read is at most MaxDepth deep
(term_depth_within/2). Both give up as soon as the limit is passed.
*/

%!  text_nesting_within(+Text, +MaxDepth) is semidet.
%
%   True if the brackets of Text, a Prolog term's text (a string of
%   characters or of UTF-8 bytes), nest at most MaxDepth deep. Brackets
%   are `(`, `[` and `{` and their closing partners; those inside quoted
%   text ('...', "...", `...`, with their escapes and doubled quotes),
%   character codes (0'c, 0'\n, 0''') and comments (`%` to the end of
%   the line, `/* ... */` unless `/*` continues a symbol atom such as
%   `+/*`) do not count. One pass over the codes; it stops at the first
%   bracket too deep. A quote right after a number other than a lone 0
%   (radix notation such as 16'ff, or 1'a', which the reader tokenizes
%   differently by context) makes it fail: quoted text must never be
%   mistaken for code, and the platform never writes that.

text_nesting_within(Text, Max) :-
    must_be(nonneg, Max),
    string_codes(Text, Codes),
    nest(Codes, other, 0, Max).

%   nest(+Codes, +Mode, +Depth, +Max): Mode is what the previous code
%   ended: word (a name, or digits inside one), zero (a number token so
%   far just "0"), number (other digits starting a token), symbol
%   (symbol characters) or other.
nest([], _, _, _).
nest([C|Cs], Mode, D, Max) :-
    octet_class(C, Class),
    nest(Class, C, Cs, Mode, D, Max).

nest(open, _, Cs, _, D, Max) :-
    D1 is D + 1,
    D1 =< Max,
    nest(Cs, other, D1, Max).
nest(close, _, Cs, _, D, Max) :-
    D1 is max(0, D - 1),
    nest(Cs, other, D1, Max).
nest(quote, Q, Cs, Mode, D, Max) :-
    (   Mode == zero                        % 0'c
    ->  char_code_rest(Cs, Rest),
        nest(Rest, other, D, Max)
    ;   Mode == number                      % 16'ff, 1'a': refused
    ->  fail
    ;   quoted(Cs, Q, Rest),
        nest(Rest, other, D, Max)
    ).
nest(dquote, Q, Cs, _, D, Max) :-
    quoted(Cs, Q, Rest),
    nest(Rest, other, D, Max).
nest(percent, _, Cs, _, D, Max) :-
    line_comment(Cs, Rest),
    nest(Rest, other, D, Max).
nest(slash, _, Cs, Mode, D, Max) :-
    (   Cs = [0'*|Cs1],
        Mode \== symbol
    ->  block_comment(Cs1, Rest),
        nest(Rest, other, D, Max)
    ;   nest(Cs, symbol, D, Max)
    ).
nest(digit, C, Cs, Mode, D, Max) :-
    (   Mode == word
    ->  Mode1 = word
    ;   ( Mode == zero ; Mode == number )
    ->  Mode1 = number
    ;   C =:= 0'0
    ->  Mode1 = zero
    ;   Mode1 = number
    ),
    nest(Cs, Mode1, D, Max).
nest(word, _, Cs, _, D, Max) :-
    nest(Cs, word, D, Max).
nest(symbol, _, Cs, _, D, Max) :-
    nest(Cs, symbol, D, Max).
nest(other, _, Cs, _, D, Max) :-
    nest(Cs, other, D, Max).

%   After 0': the code of one character: two quotes or one (0''' and
%   0''), an escape sequence, or any one character.
char_code_rest([0'', 0''|Rest], Rest) :- !.
char_code_rest([0'\\|Cs], Rest) :- !, escape_rest(Cs, Rest).
char_code_rest([_|Rest], Rest) :- !.
char_code_rest([], []).

%   Quoted text up to its closing quote Q (a doubled Q is one character).
quoted([], _, []).
quoted([C|Cs], Q, Rest) :-
    (   C =:= Q
    ->  (   Cs = [Q|Cs1]
        ->  quoted(Cs1, Q, Rest)
        ;   Rest = Cs
        )
    ;   C =:= 0'\\
    ->  escape_rest(Cs, Cs1),
        quoted(Cs1, Q, Rest)
    ;   quoted(Cs, Q, Rest)
    ).

%   After a backslash: \xHH..\ and \OOO..\ (the closing backslash is
%   optional), or one character.
escape_rest([0'x|Cs], Rest) :- !, digits_then_backslash(Cs, 16, Rest).
escape_rest([C|Cs], Rest) :- C >= 0'0, C =< 0'7, !, digits_then_backslash(Cs, 8, Rest).
escape_rest([_|Rest], Rest) :- !.
escape_rest([], []).

digits_then_backslash([C|Cs], Radix, Rest) :-
    code_type(C, xdigit(W)),
    W < Radix,
    !,
    digits_then_backslash(Cs, Radix, Rest).
digits_then_backslash([0'\\|Rest], _, Rest) :- !.
digits_then_backslash(Rest, _, Rest).

line_comment([], []).
line_comment([C|Cs], Rest) :-
    (   C =:= 0'\n
    ->  Rest = Cs
    ;   line_comment(Cs, Rest)
    ).

block_comment([], []).
block_comment([C|Cs], Rest) :-
    (   C =:= 0'*, Cs = [0'/|Rest0]
    ->  Rest = Rest0
    ;   block_comment(Cs, Rest)
    ).

%   octet_class(?Code, ?Class): the class of every code 0..255 (bytes of
%   UTF-8 text: those above 127 are parts of letters here), as clauses
%   indexed on Code; codes above 255 (text given as characters) are
%   letters too.
term_expansion(octet_classes, Clauses) :-
    findall(octet_class(C, K), ( between(0, 255, C), classify(C, K) ), Clauses0),
    append(Clauses0, [(octet_class(C, word) :- C > 255)], Clauses).

classify(C, open)    :- memberchk(C, `([{`), !.
classify(C, close)   :- memberchk(C, `)]}`), !.
classify(0'', quote) :- !.
classify(C, dquote)  :- memberchk(C, `"\``), !.
classify(0'%, percent) :- !.
classify(0'/, slash) :- !.
classify(C, digit)   :- between(0'0, 0'9, C), !.
classify(C, word)    :- ( between(0'a, 0'z, C) ; between(0'A, 0'Z, C) ; C =:= 0'_ ; C > 127 ), !.
classify(C, symbol)  :- memberchk(C, `+-*\\^<>=~:.?@#&$`), !.
classify(_, other).

octet_classes.

%!  term_depth_within(@Term, +MaxDepth) is semidet.
%
%   True if Term is at most MaxDepth deep: an atomic term or a variable
%   has depth 0, a compound one more than its deepest argument, except
%   that the elements of a list are all one level below the list,
%   however long it is. Linear in the size of Term; gives up as soon as
%   MaxDepth is exceeded.

term_depth_within(Term, Max) :-
    must_be(nonneg, Max),
    depth_ok(Term, Max).

depth_ok(T, _) :-
    \+ compound(T),
    !.
depth_ok(T, Left) :-
    Left > 0,
    Left1 is Left - 1,
    (   T = [_|_]
    ->  list_ok(T, Left1)
    ;   compound_name_arity(T, _, A),
        args_ok(1, A, T, Left1)
    ).

list_ok(L, Left) :-
    (   compound(L), L = [H|T]
    ->  depth_ok(H, Left),
        list_ok(T, Left)
    ;   depth_ok(L, Left)
    ).

args_ok(I, A, _, _) :-
    I > A,
    !.
args_ok(I, A, T, Left) :-
    arg(I, T, X),
    depth_ok(X, Left),
    I1 is I + 1,
    args_ok(I1, A, T, Left).
