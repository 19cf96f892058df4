:- module(fast_term_check,
          [ fast_term_bytes_check/3,    % +Bytes, +MaxDepth, -Result
            fast_term_decode/3,         % +Bytes, -Term, +Options
            fast_term_read/5,           % +Stream, +Len, +MaxDepth, -Term, -Result
            fast_term_check_native/1    % -Boolean
          ]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(option), [option/3]).
:- autoload(library(lists), [member/2]).

/** <module> Checking fast-term bytes before SWI-Prolog decodes them

fast_term_serialized/2 and fast_read/2 trust their input: SWI-Prolog
9.0.4's decoder (pl-rec.c) allocates the cells its header announces and
writes what the opcodes say without bounds checks, so one mutated byte
can abort the process (`copy_record: Assertion failed`) or corrupt its
memory. Bytes that come from elsewhere (a binary frame's body, a packed
state inside an agent's record) are therefore checked completely by
fast_term_bytes_check/3 before they are decoded, and fast_term_decode/3
does both.

The check walks the bytes once as the decoder would and accepts only
what fast_term_serialized/2 itself writes for a term without attributed
variables, cycles or rationals (the byte format is described in
native/fast_term_check.c): every opcode known, every length inside the
bytes, every integer in the range of its opcode, every variable number
below the count in the header and all of them used, wide text made of
valid code points, the code exactly as long as the header says and the
cells it needs on the global stack exactly the header's count, nesting
no deeper than asked (counted as wire:term_depth_within/2 counts it: a
list's elements are one level below the list, however long).

The check runs in C (native/fast_term_check.c, built by setup.sh) where
the library is built, in time linear in the number of terms (a string's
bytes are skipped: a packed table of 100,000 floats is one string); the
same walk in Prolog, over the bytes as a list of codes, is the fallback,
linear in the bytes. Both accept and refuse the same bytes
(tests/platform/test_fast_term_check.pl).
*/

:- use_module(native_library, [native_library_load/2]).
:- dynamic native/1.

:- initialization(( native_library_load(fast_term_check, Loaded),
                    assertz(native(Loaded)) ), now).

%!  fast_term_check_native(-Boolean) is det.
%
%   Boolean is `true` if the check runs in C.

fast_term_check_native(B) :-
    native(B),
    !.

%!  fast_term_bytes_check(+Bytes, +MaxDepth, -Result) is det.
%
%   Result is `true` if Bytes (a string of code points below 256) is
%   what fast_term_serialized/2 writes for a term at most MaxDepth deep
%   without attributed variables, cycles or rationals, else an
%   atom naming the first fault found (e.g. `cells_mismatch`,
%   `bad_opcode`, `too_deep`, `not_bytes`).

fast_term_bytes_check(Bytes, MaxDepth, Result) :-
    must_be(string, Bytes),
    must_be(nonneg, MaxDepth),
    (   native(true)
    ->  fast_term_check(Bytes, MaxDepth, Result)
    ;   prolog_check(Bytes, MaxDepth, Result)
    ).

%!  fast_term_decode(+Bytes, -Term, +Options) is det.
%
%   Term is what fast_term_serialized/2 decodes from Bytes, once
%   fast_term_bytes_check/3 accepted them. Options:
%
%     - max_depth(+Depth)
%       Deepest term accepted (default 10,000).
%
%   @error domain_error(fast_term_bytes, Reason) if the check refused
%   the bytes (Reason is its result).

fast_term_decode(Bytes, Term, Options) :-
    option(max_depth(Depth), Options, 10000),
    fast_term_bytes_check(Bytes, Depth, Result),
    (   Result == true
    ->  fast_term_serialized(Term, Bytes)
    ;   domain_error(fast_term_bytes, Result)
    ).

%!  fast_term_read(+Stream, +Len, +MaxDepth, -Term, -Result) is det.
%
%   Read the next Len bytes of Stream (a binary stream), check them as
%   fast_term_bytes_check/3 does and, if they pass, decode them into
%   Term. Result is `true`, the check's fault (Term is then unbound), or
%   `truncated` if the stream ended before Len bytes. In C no Prolog
%   string of the bytes is made, and on a stream that records no
%   position they are copied in bulk (read_string/3 takes some 20 ms
%   for a megabyte, fast_read/2 and this 0.2-0.5 ms); the fallback reads
%   them with read_string/3.
%
%   @error the stream's I/O error or timeout.

fast_term_read(Stream, Len, MaxDepth, Term, Result) :-
    must_be(nonneg, Len),
    must_be(nonneg, MaxDepth),
    (   native(true)
    ->  fast_term_stream_read(Stream, Len, MaxDepth, Term, Result)
    ;   read_string(Stream, Len, Bytes),
        string_length(Bytes, Got),
        (   Got < Len
        ->  Result = truncated
        ;   prolog_check(Bytes, MaxDepth, Result),
            (   Result == true
            ->  fast_term_serialized(Term, Bytes)
            ;   true
            )
        )
    ).

		 /*******************************
		 *       THE PROLOG WALK	*
		 *******************************/

%   The same walk as native/fast_term_check.c, over the codes of Bytes.
%   A fault throws fault(Reason), caught here; a failure is reported as
%   `malformed`.
prolog_check(Bytes, MaxDepth, Result) :-
    string_codes(Bytes, Codes),
    (   member(C, Codes), C > 255
    ->  Result = not_bytes
    ;   catch(( check_codes(Codes, MaxDepth) -> R = true ; R = malformed ),
              fault(Reason), R = Reason),
        Result = R
    ).

fault(Reason) :-
    throw(fault(Reason)).

check_codes([_], _) :-
    !,
    fault(too_short).
check_codes([H|Cs], Max) :-
    (   H =:= 0x76                          % an integer only
    ->  (   int64_field(Cs, _, []) -> true ; fault(bad_integer) )
    ;   H =:= 0x7a                          % an atom only
    ->  (   Cs = [9] -> true
        ;   Cs = [Op|C1], ( Op =:= 11 ; Op =:= 12 )
        ->  atom_text(Op, C1, Rest),
            ( Rest == [] -> true ; fault(trailing_bytes) )
        ;   fault(bad_opcode)
        )
    ;   ( H =:= 0x72 ; H =:= 0x62 )
    ->  header_varint(Cs, CSize, C1),
        header_varint(C1, Cells, C2),
        (   H =:= 0x62
        ->  header_varint(C2, NVars, Code),
            ( NVars > 0 -> true ; fault(bad_header) )
        ;   NVars = 0,
            Code = C2
        ),
        length(Code, Len),
        (   CSize < Len -> fault(trailing_bytes)
        ;   CSize > Len -> fault(code_past_end)
        ;   true
        ),
        ( Cells < 1<<31, NVars =< Len -> true ; fault(bad_header) ),
        walk(Code, [l(1, plain)], 0, s(Cells, NVars, Max), 0, 0)
    ;   fault(bad_header)
    ).
check_codes([], _) :-
    fault(too_short).

header_varint(Cs, V, Rest) :-
    (   varint(Cs, V, Rest) -> true ; fault(bad_header) ).

%   walk(+Codes, +Levels, +Cells, +Limits, +Seen, +Depth): Levels is a
%   stack of l(Left, Kind), the terms still to read at each open level
%   and its kind: plain, list (a list cell's level, whose tail stays on
%   it) or dict(Arity, Keys) (the keys read so far); Cells the cells
%   counted so far, Seen the variables seen so far, Depth the number of
%   levels below the root.
walk(Codes, [l(0, Kind)|Up], Cells, S, Seen, D) :-
    !,
    (   Kind = dict(_, Keys)
    ->  msort(Keys, Sorted),
        ( adjacent_equal(Sorted) -> fault(duplicate_key) ; true )
    ;   true
    ),
    (   Up == []
    ->  S = s(Want, NVars, _),
        (   Codes \== [] -> fault(trailing_bytes)
        ;   Cells =\= Want -> fault(cells_mismatch)
        ;   Seen =\= NVars -> fault(variables_mismatch)
        ;   true
        )
    ;   D1 is D - 1,
        walk(Codes, Up, Cells, S, Seen, D1)
    ).
walk([], _, _, _, _, _) :-
    !,
    fault(code_past_end).
walk([Op|C0], [l(Left, dict(Arity, Keys))|Up], Cells, S, Seen, D) :-
    Slot is Arity - Left,
    Slot > 0, Slot mod 2 =:= 0,                 % a key: an atom or a small integer
    !,
    dict_key(Op, C0, C1, Key),
    Left1 is Left - 1,
    walk(C1, [l(Left1, dict(Arity, [Key|Keys]))|Up], Cells, S, Seen, D).
walk([Op|C0], [l(Left, Kind)|Up], Cells0, S, Seen0, D) :-
    (   Kind = dict(Arity, _), Arity =:= Left,  % the tag: a variable or an atom
        \+ memberchk(Op, [1, 11, 12])
    ->  fault(bad_dict_tag)
    ;   true
    ),
    Left1 is Left - 1,
    S = s(Want, NVars, Max),
    opcode(Op, C0, C1, Cells0, Cells, NVars, Seen0, Seen, Opens),
    ( Cells =< Want -> true ; fault(cells_mismatch) ),
    (   Opens = opens(Arity1, Kind1)
    ->  (   Kind1 == list, Kind == list, Left1 =:= 0
        ->  walk(C1, [l(2, list)|Up], Cells, S, Seen, D)
        ;   D1 is D + 1,
            ( D1 =< Max -> true ; fault(too_deep) ),
            walk(C1, [l(Arity1, Kind1), l(Left1, Kind)|Up], Cells, S, Seen, D1)
        )
    ;   walk(C1, [l(Left1, Kind)|Up], Cells, S, Seen, D)
    ).

adjacent_equal([K, K|_]) :- !.
adjacent_equal([_|Ks]) :-
    adjacent_equal(Ks).

dict_key(Op, C0, C, key(Op, Text)) :-
    ( Op =:= 11 ; Op =:= 12 ),
    !,
    ( varint(C0, N, C1) -> true ; fault(bad_varint) ),
    ( take(N, C1, Text, C) -> true ; fault(atom_past_end) ),
    ( Op =:= 12, \+ ucs4_ok(Text) -> fault(bad_wide_atom) ; true ).
dict_key(4, C0, C, key(4, V)) :-
    !,
    ( int64_field(C0, V, C), V >= -(1<<56), V < 1<<56 -> true ; fault(bad_integer) ).
dict_key(_, _, _, _) :-
    fault(bad_dict_key).

%   opcode(+Op, +Codes, -Rest, +Cells0, -Cells, +NVars, +Seen0, -Seen,
%          -Opens): one term's opcode and operands; Opens is
%   opens(Arity, IsCons) for a compound with arguments, else `none`.
%   Nine arguments, on purpose: three accumulator pairs (codes, cells,
%   variables seen) threaded through the walk's inner loop, once per
%   opcode of a peer's frame; a record would be built and taken apart
%   for every opcode (the C walk in native/fast_term_check.c has them as
%   locals).
opcode(1, C0, C, Cells, Cells, NVars, Seen0, Seen, none) :-
    !,
    ( varint(C0, N, C) -> true ; fault(bad_varint) ),
    (   N < Seen0, N < NVars -> Seen = Seen0
    ;   N =:= Seen0, N < NVars -> Seen is Seen0 + 1
    ;   fault(bad_variable)
    ).
opcode(Op, C0, C, Cells0, Cells, _, Seen, Seen, none) :-
    ( Op =:= 3 ; Op =:= 4 ),
    !,
    ( int64_field(C0, V, C) -> true ; fault(bad_integer) ),
    (   V >= -(1<<56), V < 1<<56
    ->  ( Op =:= 4 -> Cells = Cells0 ; fault(bad_integer) )
    ;   ( Op =:= 3 -> Cells is Cells0 + 3 ; fault(bad_integer) )
    ).
opcode(18, C0, C, Cells0, Cells, _, Seen, Seen, none) :-
    !,
    (   C0 = [S0, S1, S2, S3|C1] -> true ; fault(bigint_past_end) ),
    S is (S0<<24) \/ (S1<<16) \/ (S2<<8) \/ S3,
    (   S >= 1<<31 -> Size is S - (1<<32) ; Size = S ),
    M is abs(Size),
    (   M >= 8, take(M, C1, Mag, C), Mag = [First|_], First =\= 0
    ->  true
    ;   fault(bad_bigint)
    ),
    (   M =:= 8
    ->  bytes_value(Mag, 0, Value),
        (   Size > 0, Value >= 1<<63 -> true
        ;   Size < 0, Value > 1<<63 -> true
        ;   fault(bad_bigint)
        )
    ;   true
    ),
    Cells is Cells0 + (M + 7) // 8 + 3.
opcode(6, C0, C, Cells0, Cells, _, Seen, Seen, none) :-
    !,
    ( varint(C0, N, C1) -> true ; fault(bad_varint) ),
    (   N >= 1, string_text(N, C1, Text, C) -> true ; fault(string_past_end) ),
    (   Text = [0'B|_] -> true
    ;   Text = [0'W, 0, 0, 0|Wide], N >= 8, ucs4_ok(Wide) -> true
    ;   Text = [0'W|_] -> fault(bad_wide_string)
    ;   fault(bad_string)
    ),
    Cells is Cells0 + (N + 8) // 8 + 2.
opcode(9, C, C, Cells, Cells, _, Seen, Seen, none) :- !.
opcode(Op, C0, C, Cells, Cells, _, Seen, Seen, none) :-
    ( Op =:= 11 ; Op =:= 12 ),
    !,
    atom_text(Op, C0, C).
opcode(14, C0, C, Cells0, Cells, _, Seen, Seen, none) :-
    !,
    (   C0 = [_, _, _, _, _, _, _, _|C] -> true ; fault(float_past_end) ),
    Cells is Cells0 + 3.
opcode(8, C, C, Cells0, Cells, _, Seen, Seen, opens(2, list)) :-
    !,
    Cells is Cells0 + 3.
opcode(13, C0, C, Cells0, Cells, _, Seen, Seen, Opens) :-
    !,
    ( varint(C0, Arity, C1) -> true ; fault(bad_varint) ),
    (   C1 = [Name|C2] -> true ; fault(code_past_end) ),
    (   Name =:= 9 -> C = C2, Kind = plain
    ;   Name =:= 10
    ->  ( Arity mod 2 =:= 1 -> C = C2, Kind = dict(Arity, []) ; fault(bad_dict) )
    ;   Arity =:= 2, Name =:= 11, C2 = [3, 0'[, 0'|, 0']|_]
    ->  fault(bad_functor_name)             % a list cell is written as 8
    ;   ( Name =:= 11 ; Name =:= 12 ) -> atom_text(Name, C2, C), Kind = plain
    ;   fault(bad_functor_name)
    ),
    Cells is Cells0 + Arity + 1,
    (   Arity > 0 -> Opens = opens(Arity, Kind) ; Opens = none ).
opcode(_, _, _, _, _, _, _, _, _) :-
    fault(bad_opcode).

%   An atom's text: a varint length and the bytes (UCS-4 for a wide one).
atom_text(Op, C0, C) :-
    ( varint(C0, N, C1) -> true ; fault(bad_varint) ),
    (   Op =:= 12
    ->  (   take(N, C1, Text, C) -> true ; fault(atom_past_end) ),
        (   ucs4_ok(Text) -> true ; fault(bad_wide_atom) )
    ;   (   skip(N, C1, C) -> true ; fault(atom_past_end) )
    ).

%   UCS-4 little-endian code points, all valid, at least one above 255.
ucs4_ok(Bytes) :-
    Bytes \== [],
    ucs4_ok(Bytes, false, true).

ucs4_ok([], Wide, Wide).
ucs4_ok([B0, B1, B2, B3|Bs], Wide0, Wide) :-
    C is B0 \/ (B1<<8) \/ (B2<<16) \/ (B3<<24),
    C =< 0x10ffff,
    (   C > 0xff -> Wide1 = true ; Wide1 = Wide0 ),
    ucs4_ok(Bs, Wide1, Wide).

%   A big-endian base-128 varint of at most 9 bytes.
varint(Codes, V, Rest) :-
    varint(Codes, 0, 0, V, Rest).

varint([C|Cs], Acc, K, V, Rest) :-
    K < 9,
    \+ ( K =:= 0, C =:= 0x80 ),              % no leading zero group
    Acc1 is (Acc << 7) \/ (C /\ 0x7f),
    (   C /\ 0x80 =:= 0
    ->  V = Acc1,
        Rest = Cs
    ;   K1 is K + 1,
        varint(Cs, Acc1, K1, V, Rest)
    ).

%   N (1..8) then N bytes, big-endian two's complement.
int64_field([N|Cs], V, Rest) :-
    N >= 1, N =< 8,
    take(N, Cs, Bytes, Rest),
    bytes_value(Bytes, 0, U),
    Bits is 8*N,
    (   U >= 1 << (Bits-1)
    ->  V is U - (1 << Bits)
    ;   V = U
    ),
    int64_bytes(V, N).

%   The bytes addInt64() writes for V: the fewest N with |V| < 2^(8N-1),
%   1 below 128, 8 for the smallest int64.
int64_bytes(V, N) :-
    A is abs(V),
    (   V =:= -(1<<63) -> N0 = 8
    ;   A < 128 -> N0 = 1
    ;   between(2, 8, N0), A < 1 << (8*N0-1) -> true
    ;   N0 = 8
    ),
    N =:= N0.

%   A string's first four bytes (all of them for a wide one, whose code
%   points are checked), the rest skipped.
string_text(N, C0, Text, C) :-
    C0 = [Mark|_],
    (   Mark == 0'W
    ->  take(N, C0, Text, C)
    ;   K is min(N, 4),
        take(K, C0, Text, C1),
        N1 is N - K,
        skip(N1, C1, C)
    ).

%   take(+N, +List, -Prefix, -Rest): the first N elements; fails if List
%   is shorter (never builds more than List holds).
take(0, L, [], L) :- !.
take(N, [X|Xs], [X|Ys], Rest) :-
    N1 is N - 1,
    take(N1, Xs, Ys, Rest).

%   skip(+N, +List, -Rest): List without its first N elements; fails if
%   it is shorter.
skip(0, L, L) :- !.
skip(N, [_|Xs], Rest) :-
    N1 is N - 1,
    skip(N1, Xs, Rest).

bytes_value([], V, V).
bytes_value([B|Bs], V0, V) :-
    V1 is (V0 << 8) \/ B,
    bytes_value(Bs, V1, V).
