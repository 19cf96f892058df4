:- module(float_vectors,
          [ vector_floats/2,            % +Vector, -Floats
            vector_packed/2,            % +Vector, -Packed
            vector_length/2,            % +Vector, -Length
            packed_vector/1,            % @Term
            vector_add/3,               % +Xs, +Ys, -Sums
            vector_mul/3,               % +Xs, +Ys, -Products
            vector_max/3,               % +Xs, +Ys, -Maxima
            vector_divide/3,            % +Xs, +N, -Quotients
            vector_times/3,             % +Xs, +W, -Products
            vector_add_scaled/4,        % +Xs, +W, +Ys, -Zs
            vector_weighted_mean/5,     % +QWs, +Ws, +Qs, +N, -Values
            float_vectors_native/1,     % -Boolean
            add_lists/3,                % +Xs, +Ys, -Sums
            mul_lists/3,                % +Xs, +Ys, -Products
            max_lists/3,                % +Xs, +Ys, -Maxima
            scale_list/3,               % +Xs, +N, -Quotients
            times_list/3,               % +Xs, +W, -Products
            add_scaled/4,               % +Xs, +W, +Ys, -Zs
            weighted_mean/5             % +QWs, +Ws, +Qs, +N, -Values
          ]).
:- autoload(library(error), [must_be/2, type_error/2, domain_error/2]).
:- autoload(library(apply), [maplist/2, maplist/3]).
:- autoload(library(lists), [member/2, append/3]).

/** <module> Float vectors: lists of floats, or packed

A vector is a list of floats or fts(String), the same list *packed*:
String is what fast_term_serialized/2 makes of it, one byte per code
point (10 bytes a float). This is the form a table crosses the Python
bridge in (pybridge/table_codec.pl), and the form the dFRL agent carries
tables in: a packed vector of 20,000 floats is asserted, serialised and
sent as one string, where a list costs SWI-Prolog some 120 ns a float to
assert and 50 ns to serialise, at every hop.

The element-wise operations below take either form and give a packed
vector when every vector argument is packed, else a list. On packed
vectors they run in C (native/float_vectors.c, built by setup.sh) where
the library is built; elsewhere, or where the C code declines (a result
that is not finite, a malformed vector), the same work is done on lists
with is/2. Both compute each element with the same floating-point
operation, so the two give identical bits (tests/platform/
test_float_vectors.pl checks it), and a run is the same with or
without the library.

A packed vector from elsewhere (a peer's agent) is checked completely
before it is decoded: fast_term_serialized/2 trusts its input, and
malformed bytes can crash the process.

Without the library, packed maths costs a decode and an encode around
each operation (some 18 ms for a sum of two 20,000-float vectors, ten
times the list's): the dFRL agent then asks its hosts for lists
(dfrl_robot_io.pl) and carries them as before.
*/

:- use_module(native_library, [native_library_load/2]).
:- dynamic native/1.

:- initialization(( native_library_load(float_vectors, Loaded),
                    assertz(native(Loaded)) ), now).

%!  float_vectors_native(-Boolean) is det.
%
%   Boolean is `true` if packed vectors are computed in C.

float_vectors_native(B) :-
    native(B),
    !.

%!  packed_vector(@Term) is semidet.
%
%   Term is fts(String) (not checked further).

packed_vector(T) :-
    compound(T),
    T = fts(S),
    string(S).

%!  vector_floats(+Vector, -Floats) is det.
%
%   Floats is Vector as a list.
%
%   @error domain_error(fts_float_list, String) for a packed vector that
%   is not the serialisation of a list of floats.

vector_floats(V, Floats) :-
    packed_vector(V),
    !,
    V = fts(S),
    check_packed(S),
    fast_term_serialized(Floats, S).
vector_floats(V, V) :-
    must_be(list, V).

%!  vector_packed(+Vector, -Packed) is det.
%
%   Packed is Vector as fts(String).
%
%   @error type_error(float, X) if an element X of a list is not a float.

vector_packed(V, P) :-
    packed_vector(V),
    !,
    V = fts(S),
    check_packed(S),
    P = V.
vector_packed(V, fts(S)) :-
    must_be(list, V),
    (   maplist(float, V)
    ->  true
    ;   member(X, V), \+ float(X)
    ->  type_error(float, X)
    ),
    fast_term_serialized(V, S).

%!  vector_length(+Vector, -Length) is det.

vector_length(V, N) :-
    packed_vector(V),
    !,
    (   native(true), fts_vector_length(V, N0)
    ->  N = N0
    ;   V = fts(S),
        check_packed(S),
        packed_length(S, N)
    ).
vector_length(V, N) :-
    length(V, N).

%!  vector_add(+Xs, +Ys, -Sums) is semidet.
%!  vector_mul(+Xs, +Ys, -Products) is semidet.
%!  vector_max(+Xs, +Ys, -Maxima) is semidet.
%
%   Element-wise sum, product and maximum (is/2's max/2) of two vectors
%   of one length; fail on vectors of different lengths.

vector_add(X, Y, Z) :- elementwise([X, Y], fts_vector_binop(add, X, Y), add_lists, Z).
vector_mul(X, Y, Z) :- elementwise([X, Y], fts_vector_binop(mul, X, Y), mul_lists, Z).
vector_max(X, Y, Z) :- elementwise([X, Y], fts_vector_binop(max, X, Y), max_lists, Z).

%!  vector_divide(+Xs, +N, -Quotients) is det.
%!  vector_times(+Xs, +W, -Products) is det.
%
%   Each element divided by the number N; each multiplied by W.

vector_divide(X, N, Z) :- elementwise([X], fts_vector_scale(divide, X, N), divided_by(N), Z).
vector_times(X, W, Z) :- elementwise([X], fts_vector_scale(times, X, W), times_by(W), Z).

divided_by(N, Xs, Zs) :- scale_list(Xs, N, Zs).
times_by(W, Xs, Zs) :- times_list(Xs, W, Zs).

%!  vector_add_scaled(+Xs, +W, +Ys, -Zs) is semidet.
%
%   Zs is Xs + W*Ys element-wise.

vector_add_scaled(X, W, Y, Z) :-
    elementwise([X, Y], fts_vector_add_scaled(X, W, Y), plus_scaled(W), Z).

plus_scaled(W, Xs, Ys, Zs) :- add_scaled(Xs, W, Ys, Zs).

%!  vector_weighted_mean(+QWs, +Ws, +Qs, +N, -Values) is semidet.
%
%   Element-wise QW/W where the weight W is positive, else Q/N (see
%   weighted_mean/5).

vector_weighted_mean(QW, W, Q, N, V) :-
    elementwise([QW, W, Q], fts_vector_weighted_mean(QW, W, Q, N), mean_of(N), V).

mean_of(N, QWs, Ws, Qs, Vs) :- weighted_mean(QWs, Ws, Qs, N, Vs).

%   elementwise(+Vectors, +Native, +OnLists, -Result): every operation
%   above. When every vector is packed, Native (a goal of the C library,
%   called with Result) computes it if the library is loaded and takes
%   them; else OnLists is called with the vectors as lists and Result,
%   and Result is packed again when they all were.
elementwise(Vs, Native, OnLists, Z) :-
    (   maplist(packed_vector, Vs)
    ->  (   native(true), call(Native, Z0)
        ->  Z = Z0
        ;   on_lists(OnLists, Vs, Zs),
            vector_packed(Zs, Z)
        )
    ;   on_lists(OnLists, Vs, Z)
    ).

on_lists(OnLists, Vs, Z) :-
    maplist(vector_floats, Vs, Ls),
    append(Ls, [Z], Args),
    Goal =.. [call, OnLists|Args],
    call(Goal).

		 /*******************************
		 *     CHECKING A PACKED ONE	*
		 *******************************/

%   The whole layout of a packed list of N floats: header, every
%   element's two tag bytes, trailer, length (in C when it is built).
check_packed(S) :-
    (   native(true)
    ->  (   fts_vector_length(fts(S), _)
        ->  true
        ;   domain_error(fts_float_list, S)
        )
    ;   (   packed_layout(S, _)
        ->  true
        ;   domain_error(fts_float_list, S)
        )
    ).

packed_length(S, N) :-
    (   packed_layout(S, N0)
    ->  N = N0
    ;   domain_error(fts_float_list, S)
    ).

packed_layout(S, N) :-
    string_codes(S, Codes),             % once: linear in the string
    (   Codes == [122, 9]
    ->  N = 0
    ;   Codes = [114|C1],
        varint(C1, V1, C2),
        varint(C2, V2, Elems),
        V2 > 0, V2 mod 6 =:= 0,
        N is V2 // 6,
        V1 =:= 10*N + 1,
        float_elements(N, Elems, [9])
    ).

%   A big-endian base-128 varint (at most 10 bytes) at the front of Codes.
varint(Codes, V, Rest) :-
    varint(Codes, 0, 0, V, Rest).

varint([C|Cs], Acc, K, V, Rest) :-
    K < 10,
    Acc1 is (Acc << 7) \/ (C /\ 0x7f),
    (   C /\ 0x80 =:= 0
    ->  V = Acc1, Rest = Cs
    ;   K1 is K + 1,
        varint(Cs, Acc1, K1, V, Rest)
    ).

%   N elements, each the tags 8, 14 and eight bytes, then Rest.
float_elements(0, Rest, Rest) :- !.
float_elements(N, [8, 14, _, _, _, _, _, _, _, _|Cs], Rest) :-
    N1 is N - 1,
    float_elements(N1, Cs, Rest).

		 /*******************************
		 *      ELEMENT-WISE ON LISTS	*
		 *******************************/

%!  add_lists(+Xs, +Ys, -Sums) is semidet.
%!  mul_lists(+Xs, +Ys, -Products) is semidet.
%!  max_lists(+Xs, +Ys, -Maxima) is semidet.
%
%   Element-wise sum, product and maximum of two lists of numbers of one
%   length (fails on lists of different lengths).

%!  scale_list(+Xs, +N, -Quotients) is det.
%!  times_list(+Xs, +W, -Products) is det.
%
%   Each element of Xs divided by N; each multiplied by W (W*X).

%!  add_scaled(+Xs, +W, +Ys, -Zs) is semidet.
%
%   Zs is Xs + W*Ys element-wise (fails on lists of different lengths).

%!  weighted_mean(+QWs, +Ws, +Qs, +N, -Values) is semidet.
%
%   Element-wise QW/W where the weight W is positive, else Q/N: the
%   visit-weighted mean of N tables from the sums of Q*W (QWs), of the
%   weights (Ws) and of Q (Qs). Fails on lists of different lengths.

%   The element-wise helpers are compiled with the optimise flag, which
%   turns is/2 into virtual-machine arithmetic: 2.5 times faster on
%   20,000-element lists. The flag is restored after them.
:- dynamic saved_optimise/1.
:- current_prolog_flag(optimise, O),
   assertz(saved_optimise(O)),
   set_prolog_flag(optimise, true).

add_lists([], [], []).
add_lists([A|As], [B|Bs], [C|Cs]) :- C is A + B, add_lists(As, Bs, Cs).

mul_lists([], [], []).
mul_lists([A|As], [B|Bs], [C|Cs]) :- C is A * B, mul_lists(As, Bs, Cs).

max_lists([], [], []).
max_lists([A|As], [B|Bs], [C|Cs]) :- C is max(A, B), max_lists(As, Bs, Cs).

scale_list([], _, []).
scale_list([A|As], N, [C|Cs]) :- C is A / N, scale_list(As, N, Cs).

add_scaled([], _, [], []).
add_scaled([A|As], W, [B|Bs], [C|Cs]) :- C is A + W*B, add_scaled(As, W, Bs, Cs).

times_list([], _, []).
times_list([A|As], W, [C|Cs]) :- C is W*A, times_list(As, W, Cs).

weighted_mean([], [], [], _, []).
weighted_mean([QW|QWs], [W|Ws], [Q|Qs], N, [V|Vs]) :-
    (   W > 0 -> V is QW / W ; V is Q / N ),
    weighted_mean(QWs, Ws, Qs, N, Vs).

:- retract(saved_optimise(O)),
   set_prolog_flag(optimise, O).
