:- module(sandbox_check,
          [ check_body/3,               % +Scratch, +Self, +Body
            with_scratch/3,             % +Preds, +Rules, :Goal
            code_refuse/2,              % +Culprit, +Why
            plain_data/1,               % @Term
            clause_parts/2,             % +Clause, -Head-Body
            check_head/1,               % +Head-Body
            scratch_module/1            % ?Module
          ]).
:- use_module(sandbox_policy, [policy_safe_goal/1]).
:- autoload(library(lists), [member/2]).

/** <module> One body through the sandbox, in a scratch module

The walk that code_safety.pl applies to the code a peer sends: the code
under check is put in a scratch module (so that library(sandbox) sees
the calls between its predicates), each body is walked by the sandbox
with the platform's policy (sandbox_policy.pl), and a refusal becomes
error(permission_error(install, code, Culprit), context(code_safety,
Why)), Culprit the offending goal or clause head.
*/

%!  code_refuse(+Culprit, +Why) is det.
%
%   Refuse the code under check.
%
%   @error permission_error(install, code, Culprit), always.

code_refuse(Culprit, Why) :-
    throw(error(permission_error(install, code, Culprit),
                context(code_safety, Why))).

%!  plain_data(@Term) is det.
%!  clause_parts(+Clause, -HeadBody) is det.
%!  check_head(+HeadBody) is det.
%
%   Term has no cycles and no attributed variables; a clause as
%   Head-Body; a clause head that code from a peer may have.
%
%   Records reach the check from frames only: a text frame cannot hold
%   attributed variables or cycles and wire.pl refuses a binary frame
%   with them, so the data is not walked again here.
%   Data with no attributed variables and no cycles: nothing runs when
%   it is unified, copied or asserted.

plain_data(T) :-
    (   acyclic_term(T), term_attvars(T, [])
    ->  true
    ;   code_refuse(data, 'cyclic terms or attributed variables')
    ).

clause_parts((H:-B), H-B) :- !.
clause_parts(H, H-true).

check_head(H-_) :-
    (   var(H)
    ->  code_refuse(clause_head(H), 'a variable as clause head')
    ;   \+ callable(H)
    ->  code_refuse(clause_head(H), 'not callable')
    ;   H = _:_
    ->  code_refuse(clause_head(H), 'a clause for another module')
    ;   functor(H, F, A), control(F/A)
    ->  code_refuse(clause_head(H), 'a control construct as clause head')
    ;   true
    ).

control((:-)/2). control((:-)/1). control((?-)/1). control((-->)/2).
control((',')/2). control((;)/2). control((->)/2). control((*->)/2).
control((\+)/1). control((@)/2).

%!  check_body(+Scratch, +Self, +Body) is det.
%
%   Walk Body, code of the agent Self (`guid` in a program) whose
%   predicates are in the module Scratch (with_scratch/3), through the
%   sandbox: conjunct by conjunct, left to right, applying the
%   unifications of the top-level conjunction to the goals after them
%   (so that Mod = m, call(Mod:G) is understood).

check_body(S, Self, (A, B)) :-
    !,
    check_body(S, Self, A),
    check_body(S, Self, B).
check_body(_, _, X = Y) :-
    !,
    ( X = Y -> true ; true ).
check_body(S, Self, G) :-
    copy_term(G, G1),
    b_setval(code_safety_self, Self),
    catch(policy_safe_goal(S:G1), E, sandbox_refusal(S, G, E)),
    b_setval(code_safety_self, '$none').

sandbox_refusal(_, _, error(permission_error(install, code, C), Ctx)) :-
    !,
    throw(error(permission_error(install, code, C), Ctx)).
sandbox_refusal(S, _, error(permission_error(call, sandboxed, G), Ctx)) :-
    !,
    unscratch(S, G, C),
    (   nonvar(Ctx), Ctx = sandbox(_, [policy(Why)|_])
    ->  code_refuse(C, Why)
    ;   code_refuse(C, 'not allowed in the sandbox')
    ).
sandbox_refusal(S, G0, error(existence_error(procedure, PI), _)) :-
    !,
    unscratch(S, PI, C),
    unscratch(S, G0, G),
    code_refuse(undefined(C, G), 'calls a predicate this node does not define').
sandbox_refusal(S, G0, error(instantiation_error, _)) :-
    !,
    unscratch(S, G0, G),
    code_refuse(unknown_call(G), 'cannot tell which predicate it calls').
sandbox_refusal(S, G0, error(Formal, _)) :-
    unscratch(S, G0, G),
    code_refuse(G, Formal).

unscratch(S, T0, T) :-
    (   T0 = M:T1, M == S
    ->  T = T1
    ;   T = T0
    ).

%!  with_scratch(+Preds, +Rules, :Goal) is semidet.
%
%   Call(Goal, Scratch) with the code under check in the module Scratch,
%   which inherits from `user` as agents' modules do, one check at a
%   time.

:- meta_predicate with_scratch(+, +, 1).

with_scratch(Preds, Rules, Goal) :-
    with_mutex(code_safety_scratch,
               setup_call_cleanup(
                   scratch_fill(Preds, Rules, S),
                   call(Goal, S),
                   scratch_clear(S))).

%!  scratch_module(?Module) is det.
%
%   The module code is checked in.

scratch_module(code_safety_scratch).

scratch_fill(Preds, Rules, S) :-
    scratch_module(S),
    scratch_clear(S),
    dynamic(S:'$scratch'/0),            % the module exists, even for no rules
    catch(( forall(( member(P, Preds), P = F/A, atom(F), integer(A) ),
                   dynamic(S:F/A)),
            forall(member(H-B, Rules),
                   ( functor(H, F, A), dynamic(S:F/A), assertz(S:(H:-B)) ))
          ),
          error(E, _),
          code_refuse(clause(E), 'cannot define it')).

scratch_clear(S) :-
    forall(( current_predicate(S:F/A),
             functor(H, F, A),
             predicate_property(S:H, dynamic),
             \+ predicate_property(S:H, imported_from(_)) ),
           abolish(S:F/A)).
