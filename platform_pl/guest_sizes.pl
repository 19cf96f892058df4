:- module(guest_sizes,
          [ text_limit/1,               % -Chars
            bits_limit/1,               % -Bits
            over_bits/3,                % +Culprit, +Bits, +Max
            check_text/2,               % +Culprit, +Chars
            check_terms/3,              % +Culprit, +Quoted, +Terms
            check_terms/4,              % +Culprit, +Quoted, +Terms, -Chars
            sink_room/3,                % +Culprit, +Out, +Chars
            list_text/4,                % +Culprit, +List, +Sep, -Mode
            format_size/3,              % +Culprit, +Format, +Args
            format_size/4,              % +Culprit, +Format, +Args, -Chars
            guest_text_size/4,          % +Term, +Quoted, +Max, -Chars
            bits/2                      % +Number, -Bits
          ]).
:- use_module(library(prolog_format), [format_spec/2]).

/** <module> How big the result of a guest's call into C will be

The estimates and limits of guest_limits.pl's checked predicates: the
characters a term is written in (guest_text_size/4), a join of atoms
(list_text/4) and one format call (format_size/3) make, the bits of a
number, against the flags dfrl_guest_text_limit and
dfrl_guest_integer_bits. Over a limit, inside a bounded call
(agent_bounds.pl) the call is stopped with '$dfrl_bound'(text_size(Limit))
or '$dfrl_bound'(integer_size(Limit)); elsewhere (and while code is
checked before it is installed) the error is resource_error(guest_text)
or resource_error(guest_integer).
*/

:- set_prolog_flag(optimise, true).     % this file: arithmetic compiled inline
:- create_prolog_flag(dfrl_guest_text_limit, 8388608, [type(integer), keep(true)]).
:- create_prolog_flag(dfrl_guest_integer_bits, 8388608, [type(integer), keep(true)]).

		 /*******************************
		 *            LIMITS		*
		 *******************************/

text_limit(Max) :- current_prolog_flag(dfrl_guest_text_limit, Max).
bits_limit(Max) :- current_prolog_flag(dfrl_guest_integer_bits, Max).

over_text(Culprit, Size, Max) :-
    over(text_size(Max), guest_text, Culprit, Size, Max).
over_bits(Culprit, Size, Max) :-
    over(integer_size(Max), guest_integer, Culprit, Size, Max).

%   Inside a bounded call the agent is stopped (and its source told);
%   elsewhere (and when checking code before it is installed) a
%   resource error.
over(Kind, Resource, Culprit, Size, Max) :-
    (   \+ nb_current(guest_limits_static, true),
        catch(agent_bounds:current_call_(_, _, _, _), _, fail)
    ->  throw('$dfrl_bound'(Kind))
    ;   throw(error(resource_error(Resource), context(Culprit, size(Size, Max))))
    ).

check_text(Culprit, Size) :-
    text_limit(Max),
    (   Size > Max -> over_text(Culprit, Size, Max) ; true ).
%   bits(+Number, -Bits): of an integer's magnitude, of a rational's
%   numerator plus denominator; 0 for a float.
bits(X, B) :-
    (   integer(X)
    ->  (   X =:= 0 -> B = 0 ; B is msb(abs(X)) + 1 )
    ;   rational(X, N, D)
    ->  bits(N, BN), bits(D, BD), B is BN + BD
    ;   B = 0
    ).
		 /*******************************
		 *             TEXT		*
		 *******************************/

%!  guest_text_size(+Term, +Quoted, +Max, -Chars) is det.
%
%   Chars is at least the number of characters of Term written (quoted
%   if Quoted is true), or some number over Max once the walk passes Max
%   (a term with shared subterms is written in full: its written size can
%   be exponential in its size on the stacks). Cyclic terms count as over.

guest_text_size(T, Quoted, Max, Size) :-
    (   cyclic_term(T)
    ->  Size is Max + 1
    ;   catch(size(T, Quoted, Max, 0, Size), over(Size), true)
    ).

size(T, Q, Max, S0, S) :-
    (   var(T) -> S1 is S0 + 24
    ;   atom(T) -> system:atom_length(T, L), chars(Q, L, C), S1 is S0 + C
    ;   string(T) -> string_length(T, L), chars(Q, L, C), S1 is S0 + C
    ;   integer(T) -> bits(T, B), S1 is S0 + B * 31 // 100 + 2
    ;   number(T) -> bits(T, B), S1 is S0 + 32 + B * 31 // 100
    ;   compound(T)
    ->  compound_name_arity(T, N, A),
        system:atom_length(N, NL),
        chars(Q, NL, C),
        S2 is S0 + C + 2 + 3 * A,
        args_size(1, A, T, Q, Max, S2, S1)
    ;   S1 is S0 + 64                       % blobs: <stream>(0x...)
    ),
    (   S1 > Max -> throw(over(S1)) ; S = S1 ).

args_size(I, A, T, Q, Max, S0, S) :-
    (   I > A
    ->  S = S0
    ;   arg(I, T, X),
        size(X, Q, Max, S0, S1),
        I1 is I + 1,
        args_size(I1, A, T, Q, Max, S1, S)
    ).

chars(true, L, C) :- !, C is 5 * L + 2.
chars(_, L, L).

text_size(T, Q, S) :-
    text_limit(Max),
    guest_text_size(T, Q, Max, S).

check_terms(Culprit, Q, Terms) :-
    check_terms(Culprit, Q, Terms, _).

check_terms(Culprit, Q, Terms, S) :-
    text_limit(Max),
    terms_size(Terms, Q, Max, 0, S),
    (   S > Max -> over_text(Culprit, S, Max) ; true ).

%!  sink_room(+Culprit, +Out, +Chars) is det.
%
%   Writing Chars more characters to Out keeps the text a sink is making
%   within dfrl_guest_text_limit. A sink is the memory stream of a
%   guest's with_output_to/2 (guest_limits.pl keeps them in the global
%   variable '$dfrl_guest_sinks'): all that its goal writes becomes one
%   string, built in C one write at a time, so what the sink already
%   holds counts with each write. Out is `current` (the current output)
%   or a stream; any other output is not a sink.

sink_room(Culprit, Out, Chars) :-
    (   nb_current('$dfrl_guest_sinks', Sinks),
        Sinks \== [],
        (   Out == current -> current_output(S) ; S = Out ),
        memberchk(S, Sinks)
    ->  character_count(S, Held),
        text_limit(Max),
        Total is Held + Chars,
        (   Total > Max -> over_text(Culprit, Total, Max) ; true )
    ;   true
    ).

terms_size([], _, _, S, S).
terms_size([T|Ts], Q, Max, S0, S) :-
    (   S0 > Max
    ->  S = S0
    ;   Max1 is Max - S0,
        guest_text_size(T, Q, Max1, S1),
        S2 is S0 + S1,
        terms_size(Ts, Q, Max, S2, S)
    ).
%   A proper list whose elements are all bound: its joined length is
%   checked (sum of elements and separators); a partial list is the
%   built-in's split mode or an error.
list_text(Culprit, L, Sep, joins) :-
    is_list(L),
    !,
    text_limit(Max),
    (   atomic(Sep) -> size(Sep, false, Max, 0, SL) ; SL = 0 ),
    catch(join_size(L, SL, Max, 0, S), over(S), true),
    (   S > Max -> over_text(Culprit, S, Max) ; true ).
list_text(_, _, _, split).

join_size([], _, _, S, S).
join_size([X|Xs], SL, Max, S0, S) :-
    (   var(X) -> S1 = S0
    ;   size(X, false, Max, S0, S2), S1 is S2 + SL
    ),
    (   S1 > Max -> throw(over(S1)) ; true ),
    join_size(Xs, SL, Max, S1, S).

		 /*******************************
		 *            FORMAT		*
		 *******************************/

%   The output of one format call, estimated from its directives and
%   arguments, within dfrl_guest_text_limit. A format that does not
%   parse is left to the built-in (which raises).
format_size(Culprit, F, Args0) :-
    format_size(Culprit, F, Args0, _).

format_size(Culprit, F, Args0, Size) :-
    (   is_list(Args0) -> Args = Args0 ; Args = [Args0] ),
    (   parsed_format(F, Spec)
    ->  text_limit(Max),
        catch(spec_size(Spec, Args, Max, 0, 0, Size), over(Size), true),
        (   Size > Max -> over_text(Culprit, Size, Max) ; true )
    ;   Size = 0
    ).

%   parsed_format(+Format, -Spec): format_spec/2 (a parser in Prolog,
%   some 20 us) once per format text; the last 1,000 are kept.
:- dynamic spec_/3.                     % Hash, Format, Spec

parsed_format(F, Spec) :-
    (   atomic(F)
    ->  term_hash(F, H),
        (   spec_(H, F0, Spec0), F0 == F
        ->  Spec = Spec0
        ;   catch(format_spec(F, Spec), _, fail),
            (   predicate_property(spec_(_, _, _), number_of_clauses(N)),
                N >= 1000
            ->  retractall(spec_(_, _, _))
            ;   true
            ),
            assertz(spec_(H, F, Spec))
        )
    ;   catch(format_spec(F, Spec), _, fail)
    ).

%   spec_size(+Spec, +Args, +Max, +Column, +Size0, -Size): Column is the
%   sum of the column stops so far (a ~N| or ~N+ can pad up to there).
spec_size([], _, _, _, S, S).
spec_size([D|Ds], Args0, Max, Col0, S0, S) :-
    (   D = text(T)
    ->  string_length(T, L), S1 is S0 + L, Args = Args0, Col = Col0
    ;   D = escape(Num0, _, Dir)
    ->  numeric(Num0, Args0, Args1, Num),
        directive(Dir, Num, Args1-Args, Max, Col0-Col, Add),
        S1 is S0 + Add
    ;   S1 = S0, Args = Args0, Col = Col0
    ),
    (   S1 > Max -> throw(over(S1)) ; true ),
    spec_size(Ds, Args, Max, Col, S1, S).

numeric(star, [N|Args], Args, N) :- !,
    (   integer(N) -> true ; throw(error(type_error(integer, N), _)) ).
numeric(number(N), Args, Args, N) :- !.
numeric(_, Args, Args, default).

num(default, D, D) :- !.
num(N, _, N).

%   directive(+Char, +Numeric, +Args0-Args, +Max, +Col0-Col, -Chars): the
%   Chars one directive adds, the arguments it takes, the column it moves to.
directive(Dir, Num, Args0-Args, Max, Col0-Col0, Add) :-
    memberchk(Dir, [w, p, q, a, k, s]),
    !,
    take(Args0, T, Args),
    (   memberchk(Dir, [p, q, k]) -> Q = true ; Q = false ),
    guest_text_size(T, Q, Max, Add0),
    num(Num, 0, N),
    Add is Add0 + N.
directive(Dir, Num, Args0-Args, _, Col0-Col0, Add) :-
    memberchk(Dir, [d, 'D', r, 'R']),
    !,
    take(Args0, T, Args),
    (   number(T) -> bits(T, B) ; B = 64 ),
    num(Num, 0, N),
    (   memberchk(Dir, [r, 'R']) -> Add is B + 2 ; Add is B * 31 // 100 * 4 // 3 + N + 4 ).
directive(Dir, Num, Args0-Args, _, Col0-Col0, Add) :-
    memberchk(Dir, [e, f, g]),
    !,
    take(Args0, T, Args),
    (   number(T) -> bits(T, B) ; B = 64 ),
    num(Num, 6, N),
    Add is N + B * 31 // 100 + 330.
directive(c, Num, Args0-Args, _, Col0-Col0, Add) :- !,
    take(Args0, _, Args),
    num(Num, 1, Add).
directive(n, Num, Args-Args, _, Col0-Col0, Add) :- !,
    num(Num, 1, Add).
directive(i, _, Args0-Args, _, Col0-Col0, 0) :- !,
    take(Args0, _, Args).
directive('|', Num, Args-Args, _, Col0-Col, Add) :- !,
    num(Num, 0, N),
    Col is max(Col0, N),
    Add = N.
directive(+, Num, Args-Args, _, Col0-Col, Add) :- !,
    num(Num, 8, N),
    Col is Col0 + N,
    Add = Col.
directive(t, _, Args-Args, _, Col-Col, 0) :- !.
directive(@, _, Args0-Args, _, Col-Col, 0) :- !,   % the goal's own output is checked
    take(Args0, _, Args).
directive(_, Num, Args-Args, _, Col-Col, Add) :-
    num(Num, 0, Add).

take([], _, []).
take([A|As], A, As).
