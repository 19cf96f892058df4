:- module(guest_limits,
          [ guest_module_init/1,        % +Module
            guest_hazard/1,             % ?Name/Arity
            guest_text_size/4,          % +Term, +Quoted, +Max, -Chars
            guest_eval/2,               % -Value, +Expression
            guest_static_refusal/2,     % +Goal, -Why
            guest_context/1,            % +Module
            guest_goal/1,               % :Goal
            guest_closure/3, guest_closure/4, guest_closure/5,
            guest_closure/6, guest_closure/7, guest_closure/8,
            guest_closure/9,
            % the checked versions, under the names guests write
            (is)/2, (<)/2, (>)/2, (=<)/2, (>=)/2, (=:=)/2, (=\=)/2,
            tab/1, tab/2,
            format/1, format/2, format/3,
            write/1, print/1, writeln/1, writeq/1, write_canonical/1,
            write_term/2, write/2, writeq/2, print/2, writeln/2,
            write_canonical/2, write_term/3,
            atom_concat/3, atomic_list_concat/2, atomic_list_concat/3,
            string_concat/3, upcase_atom/2, downcase_atom/2, string_upper/2,
            string_lower/2, term_to_atom/2, term_string/2, term_string/3,
            write_length/3, text_concat/3, with_output_to/2,
            atom_number/2, number_codes/2, number_chars/2, atom_length/2,
            atom_string/2, number_string/2, atom_codes/2, atom_chars/2,
            string_codes/2, string_chars/2, string_to_atom/2,
            nth_integer_root_and_remainder/4, divmod/4,
            sum_list/2, sumlist/2, max_list/2, min_list/2,
            aggregate_all/3, must_be/2, is_of_type/2
          ]).
:- use_module(library(prolog_format), [format_spec/2]).
:- use_module(guest_hazards, [guest_hazard/1, library_hazard/1]).
:- use_module(guest_sizes,
              [ text_limit/1, check_text/2, check_terms/3, check_terms/4, list_text/4,
                format_size/3, format_size/4, sink_room/3, guest_text_size/4 ]).
:- use_module(guest_arith, [guest_eval/2, cheap/3, int_operands/2]).
:- use_module(guest_rewrite,
              [ guest_goal/1, guest_closure/3, guest_closure/4, guest_closure/5,
                guest_closure/6, guest_closure/7, guest_closure/8, guest_closure/9 ]).
:- use_module(library(lists), []).
:- use_module(library(aggregate), []).
:- use_module(library(error), []).

/** <module> Sizes of C-level work checked before guest code does it

SWI-Prolog 9.0.4 handles signals only between Prolog calls, so a single
call into C that builds a huge atom (`format(atom(A), "~*c", [N, 0'x])`,
atomic_list_concat/2 of many copies of one long atom) or a huge integer
(`X is 7^400000000`, GMP works outside the Prolog stacks) cannot be
stopped by agent_bounds.pl's monitor, and 9.0.4 has no
max_integer_size flag. This module holds *checked versions* of those
predicates, under the names guest code writes: each estimates the size
of its result from its arguments and, over a limit, raises instead of
calling the built-in:

  | what                          | limit (flag)                           | default |
  |-------------------------------|----------------------------------------|---------|
  | characters of text one call makes (atoms, strings, output of one write or format) | dfrl_guest_text_limit | 8,388,608 |
  | bits of an integer (result or operand of a non-linear operation) | dfrl_guest_integer_bits | 8,388,608 (1 MiB) |

Arithmetic is evaluated bottom up: each node of the expression gets its
operands as numbers, and `*`, `^`, `**`, `<<`, `>>` (negative shift),
`powm`, `/`, `//`, `div`, `mod`, `rem`, `gcd`, `lcm`, rationals are
checked on their operands' bits before the node is evaluated. Text is
estimated from the arguments (atom and string lengths, digits of
integers, quoted text at 5 characters a character, a term's written
size walked with a cut-off at the limit); format/1,2,3 adds the column,
padding, repeat and precision arguments of its directives (`~Nc`, `~*c`,
`~t~N|`, `~N+`, `~Ne`, `~Nd`, `~Nn`). Library predicates that evaluate
the caller's data (sum_list/2, max_list/2, aggregate_all/3 with sum/max/
min, must_be/2 of between(L,H)) are here too.

How guest code reaches them (guest_module_init/1): an agent's module
inherits from this one (its base module, above `user`), so meta-calls
from it (`call(is, X, E)`, maplist/N, yall lambdas, findall/forall,
foldl) resolve here; and it imports each of them, because a clause
asserted into a module that does not define a system predicate itself
binds its calls to `system` at once (pl-comp.c's lookupBodyProcedure),
whatever the module inherits. sandbox_policy.pl refuses the other ways
to the built-ins: an explicit module (`system:is(X, E)`,
`call(lists:is, X, E)`, `apply:maplist(is, ...)`). Trusted modules (the
platform, the dFRL agent) never see this module and pay nothing.

Over a limit, inside a bounded call (agent_bounds.pl) the call is stopped
with '$dfrl_bound'(text_size(Limit)) or '$dfrl_bound'(integer_size(Limit))
(the agent is removed, its source told); elsewhere the error is
resource_error(guest_text) or resource_error(guest_integer).

The parts: guest_hazards.pl (which predicates), guest_sizes.pl (the
size estimates and limits), guest_arith.pl (the node-by-node
evaluator), guest_rewrite.pl (a peer's program rewritten to call
them); this module holds the checked versions themselves.
*/

:- set_prolog_flag(optimise, true).     % this file: arithmetic compiled inline

:- redefine_system_predicate(is(_,_)).
:- redefine_system_predicate(<(_,_)).
:- redefine_system_predicate(>(_,_)).
:- redefine_system_predicate(=<(_,_)).
:- redefine_system_predicate(>=(_,_)).
:- redefine_system_predicate(=:=(_,_)).
:- redefine_system_predicate(=\=(_,_)).
:- redefine_system_predicate(tab(_)).
:- redefine_system_predicate(tab(_,_)).
:- redefine_system_predicate(format(_)).
:- redefine_system_predicate(format(_,_)).
:- redefine_system_predicate(format(_,_,_)).
:- redefine_system_predicate(write(_)).
:- redefine_system_predicate(print(_)).
:- redefine_system_predicate(writeln(_)).
:- redefine_system_predicate(writeq(_)).
:- redefine_system_predicate(write_canonical(_)).
:- redefine_system_predicate(write_term(_,_)).
:- redefine_system_predicate(write(_,_)).
:- redefine_system_predicate(writeq(_,_)).
:- redefine_system_predicate(print(_,_)).
:- redefine_system_predicate(writeln(_,_)).
:- redefine_system_predicate(write_canonical(_,_)).
:- redefine_system_predicate(write_term(_,_,_)).
:- redefine_system_predicate(atom_concat(_,_,_)).
:- redefine_system_predicate(atomic_list_concat(_,_)).
:- redefine_system_predicate(atomic_list_concat(_,_,_)).
:- redefine_system_predicate(string_concat(_,_,_)).
:- redefine_system_predicate(upcase_atom(_,_)).
:- redefine_system_predicate(downcase_atom(_,_)).
:- redefine_system_predicate(string_upper(_,_)).
:- redefine_system_predicate(string_lower(_,_)).
:- redefine_system_predicate(term_to_atom(_,_)).
:- redefine_system_predicate(term_string(_,_)).
:- redefine_system_predicate(term_string(_,_,_)).
:- redefine_system_predicate(write_length(_,_,_)).
:- redefine_system_predicate(with_output_to(_,_)).
:- redefine_system_predicate(text_concat(_,_,_)).
:- redefine_system_predicate(atom_number(_,_)).
:- redefine_system_predicate(number_codes(_,_)).
:- redefine_system_predicate(number_chars(_,_)).
:- redefine_system_predicate(atom_length(_,_)).
:- redefine_system_predicate(atom_string(_,_)).
:- redefine_system_predicate(number_string(_,_)).
:- redefine_system_predicate(atom_codes(_,_)).
:- redefine_system_predicate(atom_chars(_,_)).
:- redefine_system_predicate(string_codes(_,_)).
:- redefine_system_predicate(string_chars(_,_)).
:- redefine_system_predicate(string_to_atom(_,_)).
:- redefine_system_predicate(nth_integer_root_and_remainder(_,_,_,_)).
:- redefine_system_predicate(divmod(_,_,_,_)).

:- meta_predicate
    format(+, :),
    format(+, +, :),
    write_term(?, :),
    write_term(+, ?, :),
    with_output_to(?, 0),
    aggregate_all(?, 0, -).

%   Importing a predicate a module does not export is what
%   guest_module_init/1 means to do: no warning.
:- multifile user:message_hook/3.

user:message_hook(import_private(_, guest_limits:_), warning, _).

%   This module's own arithmetic is the built-in's (its exported is/2
%   and comparisons are the checked ones, for guests).
goal_expansion(G, system:G) :-
    prolog_load_context(source, File),
    module_property(guest_limits, file(File)),
    compound(G),
    compound_name_arity(G, F, 2),
    memberchk(F, [is, <, >, =<, >=, =:=, =\=]).

%!  guest_module_init(+Module) is det.
%
%   Make Module, an agent's module, resolve the checked versions: this
%   module becomes its base module (it inherits `user` through it) and
%   each checked predicate is imported, so that clauses asserted into
%   Module afterwards call them (predicate_property/2 would report them
%   imported already, through the base module: they are imported
%   unconditionally, which is a no-op the second time). Call it before
%   any clause is asserted into Module.

guest_module_init(M) :-
    must_be_atom(M),
    set_module(M:base(guest_limits)),
    forall(( guest_hazard(PI), \+ library_hazard(PI) ),
           catch(@(import(guest_limits:PI), M), E,
                 print_message(warning, E))).

must_be_atom(M) :-
    (   atom(M) -> true ; throw(error(type_error(atom, M), _)) ).

%!  guest_context(+Module) is semidet.
%
%   Module is one where guest code runs or is checked: a call written
%   there without a module reaches this module's checked versions (an
%   agent's module), or is code under check (code_safety.pl's scratch
%   module, where a program's clauses are checked too).

guest_context(guest_limits).
guest_context(code_safety_scratch).
guest_context(M) :-
    atom(M),
    sub_atom(M, 0, _, _, 'dfrl_agent@').

%!  guest_static_refusal(+Goal, -Why) is semidet.
%
%   Goal, a call of one of the checked predicates as written in guest
%   code, is over a limit whatever happens before it: an expression, a
%   format's arguments or a tab/1 count that are known (ground) when the
%   code is checked. Why is an atom that says which size and limit.

guest_static_refusal(G, Why) :-
    callable(G),
    catch(setup_call_cleanup(b_setval(guest_limits_static, true),
                             static_check(G),
                             b_setval(guest_limits_static, false)),
          error(resource_error(R), context(Culprit, size(Size, Max))),
          true),
    nonvar(R),
    (   R == guest_integer
    ->  system:format(atom(Why), 'integer of ~D bits at ~q (over dfrl_guest_integer_bits, ~D)',
                      [Size, Culprit, Max])
    ;   system:format(atom(Why), 'text of ~D characters by ~q (over dfrl_guest_text_limit, ~D)',
                      [Size, Culprit, Max])
    ).

static_check(G) :-
    functor(G, Name, Arity),
    (   Name == is, Arity == 2
    ->  arg(2, G, E), static_eval(E)
    ;   Arity == 2, memberchk(Name, [<, >, =<, >=, =:=, =\=])
    ->  arg(1, G, A), arg(2, G, B), static_eval(A), static_eval(B)
    ;   Name == tab
    ->  arg(Arity, G, N), static_eval(N),
        (   ground(N) -> guest_eval(V, N), check_text(tab/Arity, V) ; true )
    ;   Name == format
    ->  static_format(G, Arity)
    ;   true
    ).

%   Only ground expressions are evaluated at check time (their errors,
%   other than sizes, are the run's).
static_eval(E) :-
    (   ground(E)
    ->  catch(guest_eval(_, E), error(Formal, Context),
              (   Formal = resource_error(_)
              ->  throw(error(Formal, Context))
              ;   true
              ))
    ;   true
    ).

static_format(G, Arity) :-
    (   Arity =:= 1 -> arg(1, G, F), Args = [] ; true ),
    (   Arity =:= 2 -> arg(1, G, F), arg(2, G, Args) ; true ),
    (   Arity =:= 3 -> arg(2, G, F), arg(3, G, Args) ; true ),
    (   ground(F), catch(format_spec(F, Spec), _, fail)
    ->  text_limit(Max),
        forall(member(escape(number(N), _, _), Spec),
               (   N > Max -> throw(error(resource_error(guest_text),
                                          context(format(F), size(N, Max))))
               ;   true
               )),
        (   ground(Args)
        ->  format_size(format/Arity, F, Args)
        ;   true
        )
    ;   true
    ).

member(X, [X|_]).
member(X, [_|T]) :- member(X, T).

		 /*******************************
		 *          ARITHMETIC		*
		 *******************************/

X is E :-
    (   number(E)
    ->  X = E
    ;   cheap(E, 1024, _)
    ->  system:is(X, E)
    ;   guest_eval(V, E),
        X = V
    ).
A < B :- guest_eval(X, A), guest_eval(Y, B), system:(X < Y).
A > B :- guest_eval(X, A), guest_eval(Y, B), system:(X > Y).
A =< B :- guest_eval(X, A), guest_eval(Y, B), system:(X =< Y).
A >= B :- guest_eval(X, A), guest_eval(Y, B), system:(X >= Y).
A =:= B :- guest_eval(X, A), guest_eval(Y, B), system:(X =:= Y).
A =\= B :- guest_eval(X, A), guest_eval(Y, B), system:(X =\= Y).

divmod(A, B, Q, R) :-
    int_operands(divmod/4, [A, B]),
    system:divmod(A, B, Q, R).

nth_integer_root_and_remainder(N, I, Root, Rem) :-
    int_operands(nth_integer_root_and_remainder/4, [I]),
    system:nth_integer_root_and_remainder(N, I, Root, Rem).

		 /*******************************
		 *      LIBRARY ARITHMETIC	*
		 *******************************/

sum_list(Xs, Sum) :- sum_(Xs, 0, Sum).
sumlist(Xs, Sum) :- sum_(Xs, 0, Sum).

sum_(V, _, _) :- var(V), !, throw(error(instantiation_error, _)).
sum_([], S, S).
sum_([X|Xs], S0, S) :-
    (   number(X), number(S0)
    ->  system:is(S1, S0 + X)                % adding numbers: linear
    ;   guest_eval(S1, S0 + X)
    ),
    sum_(Xs, S1, S).

max_list([H|T], Max) :- foldl_eval(T, max, H, Max0), guest_eval(Max, Max0).
min_list([H|T], Min) :- foldl_eval(T, min, H, Min0), guest_eval(Min, Min0).

foldl_eval([], _, V, V).
foldl_eval([X|Xs], Op, V0, V) :-
    E =.. [Op, V0, X],
    (   number(X), number(V0)
    ->  system:is(V1, E)                     % max, min of numbers
    ;   guest_eval(V1, E)
    ),
    foldl_eval(Xs, Op, V1, V).

%   aggregate_all/3: sum, max and min evaluate the caller's template;
%   the rest are the library's.
aggregate_all(Spec, M:Goal, Result) :-
    (   nonvar(Spec), Spec = sum(X)
    ->  system:findall(X, M:Goal, Xs), sum_(Xs, 0, Result)
    ;   nonvar(Spec), Spec = max(X), var_or_number(Result)
    ->  system:findall(X, M:Goal, Xs), Xs \== [], max_list(Xs, Result)
    ;   nonvar(Spec), Spec = min(X), var_or_number(Result)
    ->  system:findall(X, M:Goal, Xs), Xs \== [], min_list(Xs, Result)
    ;   nonvar(Spec), functor(Spec, F, _), memberchk(F, [sum, max, min])
    ->  evaluated_template(Spec),
        aggregate:aggregate_all(Spec, M:Goal, Result)
    ;   aggregate:aggregate_all(Spec, M:Goal, Result)
    ).

var_or_number(X) :- ( var(X) -> true ; number(X) ).

%   max(X, W), min(X, W): X is evaluated by the library; only numbers
%   (or a variable, bound by the goal: checked by the library's is/2 on
%   the values the goal gave, which this module cannot see) pass.
evaluated_template(Spec) :-
    arg(1, Spec, X),
    (   ( number(X) ; var(X) ) -> true
    ;   throw(error(type_error(number, X), _))
    ).

%   must_be/2, is_of_type/2: between(L, H) compares with the bounds,
%   which must be numbers, not expressions.
must_be(Type, X) :-
    checked_type(Type),
    error:must_be(Type, X).
is_of_type(Type, X) :-
    checked_type(Type),
    error:is_of_type(Type, X).

checked_type(Type) :-
    (   nonvar(Type), Type = between(L, H)
    ->  (   number(L), number(H) -> true
        ;   throw(error(type_error(number, between(L, H)), _))
        )
    ;   true
    ).

		 /*******************************
		 *             TEXT		*
		 *******************************/

%   Text conversions: the result is about as long as the input, unless
%   the input is an integer (its digits) or the output is a list.
convert(Culprit, In) :-
    (   nonvar(In)
    ->  check_terms(Culprit, false, [In])
    ;   true
    ).

atom_concat(A, B, C) :-
    (   nonvar(A), nonvar(B) -> check_terms(atom_concat/3, false, [A, B]) ; true ),
    system:atom_concat(A, B, C).
string_concat(A, B, C) :-
    (   nonvar(A), nonvar(B) -> check_terms(string_concat/3, false, [A, B]) ; true ),
    system:string_concat(A, B, C).
text_concat(A, B, C) :-
    (   nonvar(A), nonvar(B) -> check_terms(text_concat/3, false, [A, B]) ; true ),
    system:text_concat(A, B, C).
atomic_list_concat(L, A) :-
    list_text(atomic_list_concat/2, L, '', _),
    system:atomic_list_concat(L, A).
atomic_list_concat(L, Sep, A) :-
    (   nonvar(Sep) -> list_text(atomic_list_concat/3, L, Sep, _) ; true ),
    system:atomic_list_concat(L, Sep, A).

upcase_atom(A, U) :- convert(upcase_atom/2, A), system:upcase_atom(A, U).
downcase_atom(A, U) :- convert(downcase_atom/2, A), system:downcase_atom(A, U).
string_upper(A, U) :- convert(string_upper/2, A), system:string_upper(A, U).
string_lower(A, U) :- convert(string_lower/2, A), system:string_lower(A, U).
atom_number(A, N) :- ( var(A) -> convert(atom_number/2, N) ; true ), system:atom_number(A, N).
number_codes(N, C) :- convert(number_codes/2, N), system:number_codes(N, C).
number_chars(N, C) :- convert(number_chars/2, N), system:number_chars(N, C).
atom_length(A, L) :- convert(atom_length/2, A), system:atom_length(A, L).
atom_string(A, S) :- convert(atom_string/2, A), system:atom_string(A, S).
number_string(N, S) :- convert(number_string/2, N), system:number_string(N, S).
atom_codes(A, C) :- convert(atom_codes/2, A), system:atom_codes(A, C).
atom_chars(A, C) :- convert(atom_chars/2, A), system:atom_chars(A, C).
string_codes(S, C) :- convert(string_codes/2, S), system:string_codes(S, C).
string_chars(S, C) :- convert(string_chars/2, S), system:string_chars(S, C).
string_to_atom(S, A) :- convert(string_to_atom/2, S), system:string_to_atom(S, A).
term_to_atom(T, A) :-
    (   var(A) -> check_terms(term_to_atom/2, true, [T]) ; true ),
    system:term_to_atom(T, A).
term_string(T, S) :-
    (   var(S) -> check_terms(term_string/2, true, [T]) ; true ),
    system:term_string(T, S).
term_string(T, S, Opts) :-
    (   var(S) -> check_terms(term_string/3, true, [T]) ; true ),
    system:term_string(T, S, Opts).
%   write_length/3 writes to nowhere, but a term with shared subterms
%   is written in full, in C: exponential time no signal stops.
write_length(T, L, Opts) :-
    check_terms(write_length/3, true, [T]),
    system:write_length(T, L, Opts).

		 /*******************************
		 *            OUTPUT		*
		 *******************************/

%   Each write is checked alone and, into a with_output_to/2 sink, with
%   what the sink already holds (guest_sizes:sink_room/3).
write(T) :- out(write/1, false, current, T), system:write(T).
print(T) :- out(print/1, true, current, T), system:print(T).
writeln(T) :- out(writeln/1, false, current, T), system:writeln(T).
writeq(T) :- out(writeq/1, true, current, T), system:writeq(T).
write_canonical(T) :- out(write_canonical/1, true, current, T), system:write_canonical(T).
write_term(T, Opts) :- out(write_term/2, true, current, T), system:write_term(T, Opts).
write(S, T) :- out(write/2, false, S, T), system:write(S, T).
writeq(S, T) :- out(writeq/2, true, S, T), system:writeq(S, T).
print(S, T) :- out(print/2, true, S, T), system:print(S, T).
writeln(S, T) :- out(writeln/2, false, S, T), system:writeln(S, T).
write_canonical(S, T) :- out(write_canonical/2, true, S, T), system:write_canonical(S, T).
write_term(S, T, Opts) :- out(write_term/3, true, S, T), system:write_term(S, T, Opts).

out(Culprit, Quoted, Out, T) :-
    check_terms(Culprit, Quoted, [T], Size),
    sink_room(Culprit, Out, Size).

tab(N) :-
    guest_eval(V, N),
    check_text(tab/1, V),
    sink_room(tab/1, current, V),
    system:tab(V).
tab(S, N) :-
    guest_eval(V, N),
    check_text(tab/2, V),
    sink_room(tab/2, S, V),
    system:tab(S, V).

format(F) :-
    format_size(format/1, F, [], Size),
    sink_room(format/1, current, Size),
    system:format(F).
format(F, M:Args) :-
    format_size(format/2, F, Args, Size),
    sink_room(format/2, current, Size),
    system:format(F, M:Args).
format(Out, F, M:Args) :-
    format_size(format/3, F, Args, Size),
    sink_room(format/3, Out, Size),
    system:format(Out, F, M:Args).

%!  with_output_to(+Sink, :Goal) is semidet.
%
%   The built-in, with its memory stream recorded as a sink for the
%   goal's checked writes (closed sinks are dropped as new ones come).

with_output_to(Spec, G) :-
    (   nb_current('$dfrl_guest_sinks', Sinks0) -> true ; Sinks0 = [] ),
    open_sinks(Sinks0, Sinks),
    system:with_output_to(Spec, guest_limits:sink_goal(Sinks, G)).

open_sinks([], []).
open_sinks([S|Ss0], Ss) :-
    (   is_stream(S) -> Ss = [S|Ss1] ; Ss = Ss1 ),
    open_sinks(Ss0, Ss1).

sink_goal(Sinks, G) :-
    current_output(S),
    b_setval('$dfrl_guest_sinks', [S|Sinks]),
    call(G).

