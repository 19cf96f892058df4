:- module(guest_rewrite,
          [ guest_goal/1,               % :Goal
            guest_closure/3, guest_closure/4, guest_closure/5,
            guest_closure/6, guest_closure/7, guest_closure/8,
            guest_closure/9
          ]).
:- use_module(guest_hazards, [guest_hazard/1]).

:- meta_predicate
    guest_goal(0).

/** <module> A peer's program rewritten to call the checked predicates

The calls of a program a peer sent are made to reach guest_limits.pl's
checked versions of the predicates that work in C (guest_hazards.pl)
while the program loads, and its variable goals and closures when they
are called. guest_limits.pl loads this module and re-exports
guest_goal/1 and guest_closure/3..9, which the rewritten code calls as
guest_limits:guest_goal(G) and guest_limits:guest_closure(M, C, ...).
*/

		 /*******************************
		 *      PROGRAMS FROM PEERS	*
		 *******************************/

%   A program a peer sent is loaded into `user` (codeload.pl, source
%   dfrl_program://Id), which does not inherit from this module. While it
%   loads, its goals are rewritten: a call of a checked predicate without
%   a module becomes guest_limits:Goal (SWI-Prolog's expansion applies
%   this inside findall/forall goals and closures, maplist(is, ...)
%   included), and a goal or closure that is a variable in a meta-argument
%   (call(G), findall(X, G, L), maplist(C, L)) is wrapped in
%   guest_goal/1 or guest_closure/N, which rewrite it the same way when
%   it is called. Locally loaded programs are not touched.

:- multifile system:goal_expansion/2.

system:goal_expansion(G0, G) :-
    prolog_load_context(source, Source),
    atom(Source),
    sub_atom(Source, 0, _, _, 'dfrl_program://'),
    \+ prolog_load_context(module, guest_limits),
    program_goal(G0, G).

program_goal(G0, G) :-
    callable(G0),
    \+ G0 = _:_,
    b_setval(guest_limits_compiling, true),
    rewrite(G0, G1),
    b_setval(guest_limits_compiling, false),
    wrap_meta(G1, G),
    G \== G0.

%   Variables in meta-arguments of a goal (not of a control construct:
%   the expansion visits their parts) are wrapped.
wrap_meta(G0, G) :-
    (   \+ G0 = _:_,
        \+ control(G0),
        catch(predicate_property(user:G0, meta_predicate(Spec)), _, fail)
    ->  G0 =.. [Name|Args0],
        Spec =.. [_|Specs],
        wrap_vars(Specs, Args0, Args, _),
        G =.. [Name|Args]
    ;   G = G0
    ).

load_module(M) :-
    (   prolog_load_context(module, M0) -> M = M0 ; M = user ).

control((_,_)).
control((_;_)).
control((_->_)).
control((_*->_)).
control(\+ _).

wrap_vars([], [], [], _).
wrap_vars([S|Ss], [A0|As0], [A|As], Changed) :-
    (   var(A0), S == 0
    ->  A = guest_limits:guest_goal(A0), Changed = true
    ;   var(A0), integer(S), S > 0, S =< 7
    ->  load_module(M),
        A = guest_limits:guest_closure(M, A0), Changed = true
    ;   A = A0
    ),
    wrap_vars(Ss, As0, As, Changed).

%!  guest_goal(:Goal) is nondet.
%
%   Call Goal with its calls of checked predicates (at any depth of
%   control constructs, meta-arguments and yall lambdas) rewritten to
%   this module's versions.

guest_goal(M:G0) :-
    rewrite(G0, G),
    call(M:G).

%!  guest_closure(+Module, +Closure, ?A1, ...) is nondet.
%
%   As call/N of Module:Closure, rewritten as guest_goal/1 does. Module
%   is an argument, not a meta-argument, so that the load's expansion
%   leaves Closure alone (library(yall) would compile a lambda in it).
%   It has up to 9 arguments (8 and 9 included) because it stands for
%   call/N: Module, the closure and the 1 to 7 arguments a meta-argument
%   spec of SWI-Prolog can add; they are positional by nature.

guest_closure(M, C, A1) :- closure_call(M, C, [A1]).
guest_closure(M, C, A1, A2) :- closure_call(M, C, [A1,A2]).
guest_closure(M, C, A1, A2, A3) :- closure_call(M, C, [A1,A2,A3]).
guest_closure(M, C, A1, A2, A3, A4) :- closure_call(M, C, [A1,A2,A3,A4]).
guest_closure(M, C, A1, A2, A3, A4, A5) :- closure_call(M, C, [A1,A2,A3,A4,A5]).
guest_closure(M, C, A1, A2, A3, A4, A5, A6) :- closure_call(M, C, [A1,A2,A3,A4,A5,A6]).
guest_closure(M, C, A1, A2, A3, A4, A5, A6, A7) :- closure_call(M, C, [A1,A2,A3,A4,A5,A6,A7]).

%   The closure is rewritten once for a run of calls with the same
%   closure (maplist/N over a table calls it once an element): the last
%   one and its rewriting are kept in a backtrackable global variable
%   of the thread, which shares the closure's variables, so == tells it.
closure_call(M, C, Extra) :-
    (   nb_current(guest_limits_closure, C0-C1),
        C0 == C
    ->  true
    ;   length(Extra, N),
        (   nonvar(C), \+ C = _:_
        ->  rewrite_closure(N, C, C1)
        ;   C1 = C
        ),
        b_setval(guest_limits_closure, C-C1)
    ),
    closure_goal(C1, Extra, G),
    (   C1 = _:_ -> call(G) ; call(M:G) ).

closure_goal(C, Extra, G) :-
    (   var(C)
    ->  throw(error(instantiation_error, _))
    ;   C = Q:C1
    ->  closure_goal(C1, Extra, G1), G = Q:G1
    ;   C =.. L0,
        append_(L0, Extra, L),
        G =.. L
    ).

append_([], L, L).
append_([H|T], L, [H|R]) :- append_(T, L, R).

%   rewrite(+Goal0, -Goal): the run-time form of the expansion above.
rewrite(G0, G) :-
    (   var(G0)
    ->  G = G0
    ;   G0 = _:_
    ->  G = G0
    ;   G0 = (A0, B0) -> rewrite(A0, A), rewrite(B0, B), G = (A, B)
    ;   G0 = (A0 ; B0) -> rewrite(A0, A), rewrite(B0, B), G = (A ; B)
    ;   G0 = (A0 -> B0) -> rewrite(A0, A), rewrite(B0, B), G = (A -> B)
    ;   G0 = (A0 *-> B0) -> rewrite(A0, A), rewrite(B0, B), G = (A *-> B)
    ;   G0 = (\+ A0) -> rewrite(A0, A), G = (\+ A)
    ;   lambda(G0, G)
    ->  true
    ;   callable(G0),
        functor(G0, Name, Arity),
        guest_hazard(Name/Arity)
    ->  G = guest_limits:G0
    ;   callable(G0),
        catch(predicate_property(user:G0, meta_predicate(Spec)), _, fail)
    ->  G0 =.. [Name|Args0],
        Spec =.. [_|Specs],
        rewrite_args(Specs, Args0, Args),
        G =.. [Name|Args]
    ;   G = G0
    ).

rewrite_args([], [], []).
rewrite_args([S|Ss], [A0|As0], [A|As]) :-
    (   S == 0 -> rewrite(A0, A)
    ;   S == ^ -> rewrite_hat(A0, A)
    ;   integer(S), S > 0, nonvar(A0), \+ A0 = _:_
    ->  rewrite_closure(S, A0, A)
    ;   A = A0
    ),
    rewrite_args(Ss, As0, As).

rewrite_hat(G0, G) :-
    (   nonvar(G0), G0 = V^G1
    ->  rewrite_hat(G1, G2), G = V^G2
    ;   rewrite(G0, G)
    ).

%   A closure of N arguments: a checked predicate is qualified, a lambda
%   gets its body rewritten.
rewrite_closure(N, C0, C) :-
    (   lambda_closure(C0, C1)
    ->  (   nb_current(guest_limits_compiling, true)
        ->  load_module(M),
            C = guest_limits:guest_closure(M, C0)   % see below
        ;   C = C1
        )
    ;   callable(C0),
        functor(C0, Name, A0),
        A is A0 + N,
        guest_hazard(Name/A)
    ->  C = guest_limits:C0
    ;   C = C0
    ).

%   While a program loads, a lambda is wrapped whole rather than its
%   body rewritten: library(yall) compiles a lambda into a predicate of
%   its own and decides which variables it shares with the clause by
%   looking at the body, where it does not look inside Module:Goal (a
%   rewritten body lost a shared variable: max_visited.pl's N).
lambda_closure(Ps>>B0, Ps>>B) :- rewrite(B0, B).
lambda_closure(Free/L0, Free/L) :- nonvar(L0), lambda_closure(L0, L).
lambda_closure(\X^B0, \X^B) :- rewrite_hat(B0, B).

%   A lambda called with its arguments: >>(Params, Body, A1, ...).
lambda(G0, G) :-
    compound(G0),
    compound_name_arguments(G0, F, [P, B0|Rest]),
    memberchk(F, [>>, /]),
    (   F == (>>) -> rewrite(B0, B) ; nonvar(B0), lambda_closure(B0, B) ),
    compound_name_arguments(G, F, [P, B|Rest]).
