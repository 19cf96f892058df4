:- module(table_codec,
          [ encode_values/3,            % +Codec, +Floats, -Data
            decode_values/2,            % +Data, -Floats
            fts_encoded/2,              % +Values, -Data
            float_list/2                % +Numbers, -Floats
          ]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(apply), [maplist/3]).

/** <module> The Prolog side of the table codecs (the one place that knows their format)

A table's values cross between an agent thread and the Python host as one
string, Data = fts(String) or text(String). The Python side of the same
formats is the module `dfrl.pybridge.codec`; the test
tests/pybridge/test_codec_agreement.py checks that both sides produce the
same bytes.

  - fts: the string fast_term_serialized/2 makes of a list of floats, whose
    code points are these bytes (N floats, N > 0):

        114, varint(10N+1), varint(6N), N x [8, 14, <float64 LE>], 9

    and `122, 9` for the empty list. A varint is big-endian base 128 with
    the high bit set on every byte but the last. fast_term_serialized/2
    aborts the process on malformed input, so decode_values/2 checks the
    header and the trailer first, and the host selects fts only after its
    start-up self-test showed its encoder makes exactly these bytes.
  - text: comma-separated floats as SWI-Prolog writes them (`1.0Inf`,
    `-1.0Inf`, `1.5NaN` for the non-finite ones); slower, but safe.
*/

%!  encode_values(+Codec, +Floats, -Data) is det.
%
%   Data is the list Floats (floats only) in Codec, `fts` or `text`.

encode_values(fts, Values, fts(String)) :-
    fast_term_serialized(Values, String).
encode_values(text, Values, text(String)) :-
    atomic_list_concat(Values, ',', Atom),
    atom_string(Atom, String).

%!  decode_values(+Data, -Floats) is det.
%
%   Floats is the list encoded by Data (fts(String) or text(String)).
%
%   @error domain_error(fts_float_list, String) if an fts string does not
%   have the header and trailer of a float list.
%   @error domain_error(bridge_values, Data) for any other Data.

decode_values(fts(String), Values) :-
    !,
    fts_check(String),
    fast_term_serialized(Values, String).
decode_values(text(String), Values) :-
    !,
    must_be(string, String),
    (   String == ""
    ->  Values = []
    ;   split_string(String, ",", "", Parts),
        maplist(text_float, Parts, Values)
    ).
decode_values(Data, _) :-
    domain_error(bridge_values, Data).

%   (A float is taken as it is: float/1 of an infinite float or NaN raises
%   an evaluation error, and the fts codec passes them through too.)

text_float(Text, Float) :-
    number_string(Number, Text),
    (   float(Number)
    ->  Float = Number
    ;   Float is float(Number)
    ).

%   fts_check(+String)
%
%   Cheap sanity check before fast_term_serialized/2 sees String: the header
%   and the last byte of a float list. (string_code/3 copies the whole
%   string; sub_string/5 with a fixed start does not.)

fts_check(String) :-
    must_be(string, String),
    string_length(String, Len),
    (   Len >= 2,
        sub_string(String, 0, 1, _, First),
        Last is Len - 1,
        sub_string(String, Last, 1, 0, "\t"),
        (   First == "r"
        ->  Len > 3
        ;   First == "z"
        ->  Len == 2
        )
    ->  true
    ;   domain_error(fts_float_list, String)
    ).

%!  fts_encoded(+Values, -Data) is semidet.
%
%   Data is fts(String), the encoding of Values as they are, if String has
%   exactly the length of an encoded list of length(Values) floats. That is
%   a cheap stand-in for a pass over Values: the host checks every element's
%   tag and refuses a list in which one is not a float (only a contrived mix
%   of other terms has that length), and the caller then converts with
%   float_list/2. Fails otherwise.

fts_encoded(Values, fts(String)) :-
    fast_term_serialized(Values, String),
    string_length(String, Len),
    length(Values, N),
    fts_length(N, Len).

fts_length(0, 2) :- !.
fts_length(N, Len) :-
    Size is 10*N + 1,
    Cells is 6*N,
    varint_length(Size, L1),
    varint_length(Cells, L2),
    Len =:= 2 + L1 + L2 + 10*N.

varint_length(X, L) :-
    (   X < 128
    ->  L = 1
    ;   Y is X >> 7,
        varint_length(Y, L0),
        L is L0 + 1
    ).

%!  float_list(+Numbers, -Floats) is det.
%
%   Floats is Numbers with every number as a float. The common case (all
%   floats already) is one tight pass and no copy.
%
%   @error type_error(number, X) for the first element X that is not a
%   number.

float_list(Values, Values) :-
    all_floats(Values),
    !.
float_list(Values0, Values) :-
    maplist(to_float, Values0, Values).

all_floats([]).
all_floats([X|T]) :-
    float(X),
    all_floats(T).

to_float(X, F) :-
    must_be(number, X),
    F is float(X).
